//! Reading a recording back for a replay: one streaming pass over the MCAP file, in file order.
//!
//! [`RecordingReader`] reads the file piece by piece through `mcap`'s sans-I/O linear reader
//! (no seeking, no whole-file read: memory holds one chunk being decompressed, and one record,
//! an attached model at most [`crate::model_files::MAX_ATTACHED_MODEL_BYTES`]), and hands out, in the
//! order the writer put them: the models stored as attachments, the run's metadata record
//! ([`RunInfo`]), every robot's replay step ([`ReplayStep`]) on the `/robot_<i>/replay`
//! channels, the record of each model swapped in during the run ([`SwappedModel`], after its
//! attachment and before the steps it decided), and how the run ended ([`RunEnd`]); every other
//! channel is skipped.
//!
//! A file cut short (a crash, a full disk, a copy that stopped) is read up to the cut: the steps
//! before it are handed out, and then [`ReadError::Truncated`] says at which byte the readable
//! part ends, so a replay can report what it compared and still fail. The MCAP writer starts a
//! chunk with a header whose lengths are placeholders (all ones) and fills them in when it closes
//! the chunk, so a writer killed (or stopped by a full disk) inside a chunk leaves such a header;
//! `Framing` follows the file's top-level records by their lengths as the bytes are read and
//! ends the file before an unclosed chunk, so the reader stops after the last whole chunk. A file that is not MCAP,
//! holds no replay channel, or has steps in a layout this build does not read is refused with
//! the file named and the fix ([`ReadError`]).

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::Read as _;
use std::os::unix::fs::FileExt as _;
use std::path::{Path, PathBuf};

use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

pub use crate::read_error::ReadError;
use crate::replay::{self, ReplayStep};
use crate::swap::{SWAP_METADATA, SwappedModel};
use crate::tick::{RUN_END_METADATA, RunEnd};

/// The name of the run's metadata record.
pub const RUN_METADATA: &str = "formation.run";

/// The largest record (other than a chunk, which is decompressed as it streams) a reader takes:
/// an attached model at its cap, and room for its header.
const MAX_RECORD_BYTES: u64 = crate::model_files::MAX_ATTACHED_MODEL_BYTES + (1 << 20);

/// One item of a recording, in file order.
#[derive(Debug, Clone, PartialEq)]
pub enum RecordingItem {
    /// A model stored in the recording: its attachment name (`models/<sha256>.onnx`) and bytes.
    Model {
        /// The attachment's name.
        name: String,
        /// The model's bytes.
        bytes: Vec<u8>,
    },
    /// The run's metadata record.
    Run(RunInfo),
    /// One robot's tick on its replay channel.
    Step(ReplayStep),
    /// A model swapped in during the run (its attachment, when stored, came before).
    Swap(SwappedModel),
    /// How the run ended (after its last step; recordings made before it was written have none).
    End(RunEnd),
}

/// How a recording holds one of its models.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ModelStorage {
    /// A shipped model, referenced by its path (and hash) only.
    Shipped,
    /// Stored in the recording as the attachment of this name.
    Attachment(String),
    /// Not stored: a recording made from outside the team (`formation record --connect`), whose
    /// world stored it as an attachment of its own recording, on its own host
    /// ([`NOT_STORED_PREFIX`]); the model is found at its path, or given with `--model`.
    NotStored,
}

/// How a recording made from outside begins the `model.N.stored` value of a model that the
/// world's own recording stores as an attachment (followed by what the world's said).
pub const NOT_STORED_PREFIX: &str = "not stored (recorded live; the world's ";

/// One model a recording names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordedModel {
    /// The model file the run loaded.
    pub path: PathBuf,
    /// Its SHA-256, as lowercase hex.
    pub sha256: String,
    /// Where its bytes are.
    pub storage: ModelStorage,
}

/// The run's metadata record (`formation.run`), as a replay needs it.
#[derive(Debug, Clone, PartialEq)]
pub struct RunInfo {
    /// Every key, as written.
    pub raw: BTreeMap<String, String>,
    /// The distinct models, in order of first use.
    pub models: Vec<RecordedModel>,
    /// Each robot's index in [`RunInfo::models`].
    pub robot_models: Vec<usize>,
    /// `in-process`, `lockstep` or `realtime`.
    pub clock: String,
    /// The world's LIDAR range \[m\] as the agents were told it (recordings made before it was
    /// written have only the `f32` of each step).
    pub lidar_max_range_m: Option<f64>,
    /// The robots' wheels as the agents were told them (recordings made before 2026-12-07 have
    /// none: their agents were told no top speed, and replay so).
    pub wheels: formation_proto::WheelLimits,
}

impl RunInfo {
    /// Reads the metadata record's keys; a malformed model entry is [`ReadError::Metadata`].
    pub fn parse(path: &Path, raw: BTreeMap<String, String>) -> Result<RunInfo, ReadError> {
        let bad = |key: &str, why: &str| ReadError::Metadata {
            path: path.to_path_buf(),
            record: RUN_METADATA,
            key: key.to_owned(),
            why: why.to_owned(),
        };
        let mut models = Vec::new();
        while let Some(model_path) = raw.get(&format!("model.{}.path", models.len())) {
            let k = models.len();
            let sha_key = format!("model.{k}.sha256");
            let sha256 = raw.get(&sha_key).ok_or_else(|| bad(&sha_key, "missing"))?;
            let stored_key = format!("model.{k}.stored");
            let stored = raw.get(&stored_key).map_or("", String::as_str);
            let storage = match (stored, stored.strip_prefix("attachment ")) {
                ("shipped", _) => ModelStorage::Shipped,
                (_, Some(name)) => ModelStorage::Attachment(name.to_owned()),
                (not, _) if not.starts_with(NOT_STORED_PREFIX) => ModelStorage::NotStored,
                _ => {
                    return Err(bad(
                        &stored_key,
                        "neither `shipped`, `attachment NAME` nor `not stored`",
                    ));
                }
            };
            models.push(RecordedModel {
                path: PathBuf::from(model_path),
                sha256: sha256.clone(),
                storage,
            });
        }
        let robot_models = match raw.get("robot_models").map(String::as_str) {
            None | Some("") => Vec::new(),
            Some(list) => list
                .split(',')
                .map(|k| k.parse::<usize>().ok().filter(|&k| k < models.len()))
                .collect::<Option<Vec<_>>>()
                .ok_or_else(|| bad("robot_models", "not a list of model indexes"))?,
        };
        let lidar_max_range_m = raw
            .get("lidar_max_range_m")
            .map(|v| v.parse::<f64>())
            .transpose()
            .map_err(|_| bad("lidar_max_range_m", "not a number"))?;
        let limit = |key: &str| {
            raw.get(key)
                .map(|v| v.parse::<f64>().ok().filter(|l| l.is_finite() && *l > 0.0))
                .map(|l| l.ok_or_else(|| bad(key, "not a finite number > 0")))
                .transpose()
        };
        let wheels = formation_proto::WheelLimits {
            max_speed: limit(crate::setup::MAX_WHEEL_SPEED_KEY)?,
            max_accel: limit(crate::setup::MAX_WHEEL_ACCEL_KEY)?,
        };
        Ok(RunInfo {
            clock: raw.get("clock").cloned().unwrap_or_default(),
            models,
            robot_models,
            lidar_max_range_m,
            wheels,
            raw,
        })
    }
}

/// The MCAP magic, which starts (and ends) a file.
const MAGIC_LEN: u64 = 8;
/// A record's opcode and length, which start it.
const OPCODE_LEN_SIZE: u64 = 9;
/// The opcodes the framing looks for.
const OP_CHUNK: u8 = 0x06;
const OP_DATA_END: u8 = 0x0F;
/// The length the MCAP writer puts in a chunk's header until it closes the chunk.
const PLACEHOLDER_LENGTH: u64 = u64::MAX;

/// The file's top-level records, followed by their lengths as the file is read, to find a chunk
/// the writer never closed (its length still the placeholder) before the MCAP reader gets it.
#[derive(Debug)]
struct Framing {
    /// Where the next top-level record starts (`None` once the data section is over, or the
    /// file ends inside a record's opcode and length).
    next_record: Option<u64>,
    /// Where an unclosed chunk starts: the file is read as if it ended there.
    unclosed_chunk: Option<u64>,
}

impl Framing {
    fn new() -> Framing {
        Framing {
            next_record: Some(MAGIC_LEN),
            unclosed_chunk: None,
        }
    }

    /// Follows the records that start before `until` (reading their opcode and length from
    /// `file`, without moving its cursor); returns where the readable part of the file ends, if
    /// an unclosed chunk starts before `until`.
    fn scan(&mut self, file: &File, until: u64) -> std::io::Result<Option<u64>> {
        while let Some(at) = self.next_record.filter(|&at| at < until) {
            let mut head = [0u8; OPCODE_LEN_SIZE as usize];
            if !read_exact_at(file, &mut head, at)? {
                self.next_record = None;
                break;
            }
            let opcode = head[0];
            let len = u64::from_le_bytes(head[1..].try_into().unwrap_or_default());
            if opcode == OP_CHUNK && len == PLACEHOLDER_LENGTH {
                self.unclosed_chunk = Some(at);
                self.next_record = None;
                break;
            }
            self.next_record = if opcode == OP_DATA_END {
                None
            } else {
                at.checked_add(OPCODE_LEN_SIZE)
                    .and_then(|end| end.checked_add(len))
            };
        }
        Ok(self.unclosed_chunk)
    }
}

/// Fills `buf` from `file` at `offset`; false if the file ends first.
fn read_exact_at(file: &File, buf: &mut [u8], offset: u64) -> std::io::Result<bool> {
    let mut filled = 0;
    while filled < buf.len() {
        match file.read_at(&mut buf[filled..], offset + filled as u64) {
            Ok(0) => return Ok(false),
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(true)
}

/// A recording being read, front to back.
pub struct RecordingReader {
    path: PathBuf,
    file: File,
    reader: LinearReader,
    framing: Framing,
    /// The chunk being read, its records read one by one ([`crate::bounds::ChunkRecords`]).
    chunk: Option<crate::bounds::ChunkRecords>,
    /// The options of the file's reader, which a chunk's reader shares.
    options: LinearReaderOptions,
    /// Bytes taken from the file so far.
    read: u64,
    /// Schema id → its type name.
    schemas: HashMap<u16, String>,
    /// Channel id → topic, for replay channels only.
    replay_channels: HashMap<u16, String>,
    /// Every topic seen.
    topics: Vec<String>,
    /// Whether any record was read (else a failure means "not MCAP").
    any_record: bool,
    done: bool,
}

impl std::fmt::Debug for RecordingReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecordingReader")
            .field("path", &self.path)
            .field("read", &self.read)
            .finish_non_exhaustive()
    }
}

impl RecordingReader {
    /// Opens `path` to read; only a regular file.
    pub fn open(path: &Path) -> Result<RecordingReader, ReadError> {
        let io = |source| ReadError::Io {
            path: path.to_path_buf(),
            source,
        };
        let meta = std::fs::metadata(path).map_err(io)?;
        if !meta.is_file() {
            return Err(ReadError::NotAFile {
                path: path.to_path_buf(),
                kind: formation_proto::files::file_kind(&meta),
            });
        }
        let file = File::open(path).map_err(io)?;
        let options = LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_record_length_limit(usize::try_from(MAX_RECORD_BYTES).unwrap_or(usize::MAX))
            .with_emit_chunks(true);
        Ok(RecordingReader {
            path: path.to_path_buf(),
            file,
            reader: LinearReader::new_with_options(options.clone()),
            chunk: None,
            options,
            framing: Framing::new(),
            read: 0,
            schemas: HashMap::new(),
            replay_channels: HashMap::new(),
            topics: Vec::new(),
            any_record: false,
            done: false,
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes read so far.
    pub fn bytes_read(&self) -> u64 {
        self.read
    }

    /// The next item, or `None` at the end of a complete file that has a replay channel.
    pub fn next_item(&mut self) -> Result<Option<RecordingItem>, ReadError> {
        while !self.done {
            let in_chunk = self.chunk.is_some();
            let (opcode, data) = if let Some(chunk) = self.chunk.as_mut() {
                match chunk.next_record() {
                    Some(Ok(record)) => record,
                    Some(Err(e)) => return Err(self.failure(e)),
                    None => {
                        self.chunk = None;
                        continue;
                    }
                }
            } else {
                let Some(event) = self.reader.next_event() else {
                    self.done = true;
                    break;
                };
                match event {
                    Ok(LinearReadEvent::ReadRequest(need)) => {
                        self.fill(need)?;
                        continue;
                    }
                    Ok(LinearReadEvent::Record { opcode, data }) => (opcode, data.to_vec()),
                    Err(e) => return Err(self.failure(e)),
                }
            };
            self.any_record = true;
            if opcode == crate::bounds::CHUNK && !in_chunk {
                self.chunk = Some(crate::bounds::ChunkRecords::new(
                    &data,
                    self.options.clone(),
                ));
                continue;
            }
            if !crate::bounds::READ_OPCODES.contains(&opcode) {
                continue;
            }
            if let Err(source) = crate::bounds::check(opcode, &data) {
                self.done = true;
                return Err(ReadError::BadLength {
                    path: self.path.clone(),
                    read: self.read,
                    source,
                });
            }
            let record = match mcap::parse_record(opcode, &data) {
                Ok(record) => record,
                Err(e) => return Err(self.failure(e)),
            };
            if let Some(item) = self.take(record)? {
                return Ok(Some(item));
            }
        }
        if self.replay_channels.is_empty() {
            return Err(ReadError::NoReplayChannel {
                path: self.path.clone(),
                topics: std::mem::take(&mut self.topics),
            });
        }
        Ok(None)
    }

    /// Reads up to `need` more bytes into the MCAP reader (0 at the end of the file).
    fn fill(&mut self, need: usize) -> Result<(), ReadError> {
        let mut want = need.clamp(1, 1 << 20);
        let io = |source| ReadError::Io {
            path: self.path.clone(),
            source,
        };
        let until = self.read.saturating_add(want as u64);
        if let Some(end) = self.framing.scan(&self.file, until).map_err(io)? {
            // An unclosed chunk: the file ends where it begins.
            want = usize::try_from(end.saturating_sub(self.read)).unwrap_or(want);
            if want == 0 {
                self.reader.notify_read(0);
                return Ok(());
            }
        }
        let buf = self.reader.insert(want);
        let n = loop {
            match self.file.read(buf) {
                Ok(n) => break n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(source) => {
                    return Err(ReadError::Io {
                        path: self.path.clone(),
                        source,
                    });
                }
            }
        };
        self.reader.notify_read(n);
        self.read += n as u64;
        Ok(())
    }

    /// The error for the MCAP reader's `error`: not MCAP, truncated, or corrupt.
    fn failure(&mut self, error: mcap::McapError) -> ReadError {
        self.done = true;
        match error {
            mcap::McapError::BadMagic if !self.any_record => ReadError::NotMcap {
                path: self.path.clone(),
            },
            mcap::McapError::UnexpectedEof if !self.any_record && self.read < MAGIC_LEN => {
                ReadError::NotMcap {
                    path: self.path.clone(),
                }
            }
            // The magic was read (else the error would be `BadMagic`), and no whole record.
            mcap::McapError::UnexpectedEof if !self.any_record => ReadError::TooShort {
                path: self.path.clone(),
                size: self.read,
            },
            mcap::McapError::UnexpectedEof => ReadError::Truncated {
                path: self.path.clone(),
                read: self.read,
                unclosed_chunk: self.framing.unclosed_chunk,
            },
            source => ReadError::Corrupt {
                path: self.path.clone(),
                read: self.read,
                source,
            },
        }
    }

    /// What a record adds: an item, or only what later records need (schemas, channels).
    fn take(&mut self, record: Record<'_>) -> Result<Option<RecordingItem>, ReadError> {
        match record {
            Record::Schema { header, .. } => {
                self.schemas.insert(header.id, header.name);
            }
            Record::Channel(channel) => {
                let is_replay = self
                    .schemas
                    .get(&channel.schema_id)
                    .is_some_and(|name| name == replay::TYPE_NAME);
                if !self.topics.contains(&channel.topic) {
                    self.topics.push(channel.topic.clone());
                }
                if is_replay {
                    self.replay_channels.insert(channel.id, channel.topic);
                }
            }
            Record::Attachment { header, data, .. } => {
                return Ok(Some(RecordingItem::Model {
                    name: header.name,
                    bytes: data.into_owned(),
                }));
            }
            Record::Metadata(metadata) if metadata.name == RUN_METADATA => {
                let info = RunInfo::parse(&self.path, metadata.metadata)?;
                return Ok(Some(RecordingItem::Run(info)));
            }
            Record::Metadata(metadata) if metadata.name == RUN_END_METADATA => {
                let end = RunEnd::from_metadata(&self.path, &metadata.metadata)?;
                return Ok(Some(RecordingItem::End(end)));
            }
            Record::Metadata(metadata) if metadata.name == SWAP_METADATA => {
                let swapped = SwappedModel::from_metadata(&self.path, &metadata.metadata)?;
                return Ok(Some(RecordingItem::Swap(swapped)));
            }
            Record::Message { header, data } => {
                if let Some(topic) = self.replay_channels.get(&header.channel_id) {
                    let step = ReplayStep::from_cdr(&data).map_err(|source| ReadError::Step {
                        path: self.path.clone(),
                        topic: topic.clone(),
                        source,
                    })?;
                    return Ok(Some(RecordingItem::Step(step)));
                }
            }
            _ => {}
        }
        Ok(None)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use formation_proto::wire::TickOutcome;
    use formation_proto::{Goal, WheelCmd};

    fn step(tick: u64) -> ReplayStep {
        ReplayStep {
            robot: 0,
            tick,
            time: tick as f64 * 0.05,
            heading: 0.1,
            goal: Goal {
                phi_star: 0.0,
                d_star: 1.0,
                v_star: 0.2,
            },
            max_range: 5.0,
            ranges: vec![1.0; 90],
            command: WheelCmd::new(0.1, 0.2),
            outcome: TickOutcome::Fresh,
            lag_ticks: 0,
            model_id: "m-00000000".into(),
        }
    }

    /// An MCAP file with one channel of `type_name` on `topic`, holding `payloads` (one per
    /// tenth of a second, so that several chunks are written).
    fn write(path: &Path, type_name: &str, topic: &str, payloads: &[Vec<u8>]) {
        let file = std::io::BufWriter::new(File::create(path).unwrap());
        let options = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(2048));
        let mut w = mcap::Writer::with_options(file, options).unwrap();
        let schema = w.add_schema(type_name, "ros2msg", b"").unwrap();
        let channel = w
            .add_channel(schema, topic, "cdr", &BTreeMap::new())
            .unwrap();
        for (i, data) in payloads.iter().enumerate() {
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: i as u32,
                log_time: i as u64 * 100_000_000,
                publish_time: i as u64 * 100_000_000,
            };
            w.write_to_known_channel(&header, data).unwrap();
        }
        w.finish().unwrap();
    }

    /// Every item of the recording at `path`, and how its reading ended.
    pub(crate) fn read_items(path: &Path) -> (Vec<RecordingItem>, Result<(), ReadError>) {
        let mut reader = RecordingReader::open(path).unwrap();
        let mut items = Vec::new();
        loop {
            match reader.next_item() {
                Ok(Some(item)) => items.push(item),
                Ok(None) => return (items, Ok(())),
                Err(e) => return (items, Err(e)),
            }
        }
    }

    /// Every replay step of the recording at `path`, and how its reading ended.
    fn read_all(path: &Path) -> (Vec<ReplayStep>, Result<(), ReadError>) {
        let (items, end) = read_items(path);
        let steps = items
            .into_iter()
            .filter_map(|item| match item {
                RecordingItem::Step(step) => Some(step),
                _ => None,
            })
            .collect();
        (steps, end)
    }

    fn payloads(n: u64) -> Vec<Vec<u8>> {
        (0..n).map(|t| step(t).to_cdr().unwrap()).collect()
    }

    #[test]
    fn every_step_is_read_back_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.mcap");
        write(&path, replay::TYPE_NAME, "/robot_0/replay", &payloads(40));
        let (steps, end) = read_all(&path);
        end.unwrap();
        assert_eq!(steps.len(), 40);
        assert_eq!(steps[39], step(39));
    }

    #[test]
    fn a_file_that_is_not_mcap_or_empty_is_refused_as_such() {
        let dir = tempfile::tempdir().unwrap();
        for (name, bytes) in [("text", &b"hello, world\n"[..]), ("empty", &b""[..])] {
            let path = dir.path().join(name);
            std::fs::write(&path, bytes).unwrap();
            let (_, end) = read_all(&path);
            let err = end.unwrap_err();
            assert!(matches!(err, ReadError::NotMcap { .. }), "{name}: {err}");
        }
        let err = RecordingReader::open(dir.path()).unwrap_err();
        assert!(matches!(err, ReadError::NotAFile { .. }), "{err}");
    }

    #[test]
    fn a_file_without_a_replay_channel_names_its_topics() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("chatter.mcap");
        write(
            &path,
            "std_msgs/msg/String",
            "/chatter",
            &[vec![0, 1, 0, 0]],
        );
        let err = read_all(&path).1.unwrap_err();
        assert!(matches!(err, ReadError::NoReplayChannel { .. }), "{err}");
        assert!(err.to_string().contains("/chatter"), "{err}");
    }

    #[test]
    fn a_truncated_file_gives_its_steps_then_says_where_it_ends() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.mcap");
        write(&path, replay::TYPE_NAME, "/robot_0/replay", &payloads(200));
        let bytes = std::fs::read(&path).unwrap();
        let cut = dir.path().join("cut.mcap");
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
        let (steps, end) = read_all(&cut);
        let err = end.unwrap_err();
        assert!(
            matches!(err, ReadError::Truncated { read, .. } if read == bytes.len() as u64 / 2),
            "{err}"
        );
        assert!(!steps.is_empty() && steps.len() < 200, "{}", steps.len());
        assert_eq!(steps[0], step(0));
    }

    #[test]
    fn a_step_of_another_version_is_refused_naming_the_version() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v2.mcap");
        let mut payload = step(0).to_cdr().unwrap();
        payload[4] = 2;
        write(&path, replay::TYPE_NAME, "/robot_0/replay", &[payload]);
        let err = read_all(&path).1.unwrap_err();
        assert!(
            matches!(
                &err,
                ReadError::Step {
                    source: crate::replay::ReplayError::Version { found: 2 },
                    ..
                }
            ),
            "{err}"
        );
    }
}
