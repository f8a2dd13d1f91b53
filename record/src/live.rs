//! Recording a live team from outside (`formation record --connect`): the one definition of
//! what a world hands a remote recorder, and the recorder's side that turns it into the very
//! file `--record` writes.
//!
//! The world sends, in order on one reliable channel, per run: a [`LiveSetup`] (the team, the
//! run's place among the launch's runs, and the run's finished metadata record, models hashed by
//! the world, since a recorder on another host cannot read them), then a [`TickRecord`] per
//! tick (exactly what its own recorder gets), then the end of the run with the state after its
//! last step ([`FinalSample`], none when it stopped early). Each message is little-endian bytes
//! ([`encode`] / [`decode`]) that begin with [`MAGIC`] and [`FORMAT_VERSION`]; a reader refuses
//! a version it does not know ([`LiveError::Version`]). Floats travel as their bits, so a NaN
//! command and every scan come out bit for bit.
//!
//! [`LiveRecording`] consumes the messages and writes each run with [`RecordingFile`]: a run's
//! file is created at its first tick (or at its end, when it had none), so a recorder that joins
//! a run late records from the tick it joined at and says so in the metadata (`live.first_tick`,
//! `live.complete_from_start`); the messages of the ticks it saw are the same bytes as the
//! world's own recording.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use formation_proto::wire::TickOutcome;
use formation_proto::{GabrielRule, Goal, NeighbourRule, Pose, WheelCmd};

use crate::error::RecordError;
use crate::file::{RecordingFile, RecordingSummary};
use crate::read::NOT_STORED_PREFIX;
use crate::setup::{RecordingSetup, TeamSetup};
use crate::target::RecordTarget;
use crate::tick::{FinalSample, SentCommand, TickRecord};

/// The first bytes of every live message.
pub const MAGIC: [u8; 4] = *b"FMLV";

/// The version of the layout this crate writes and reads.
pub const FORMAT_VERSION: u16 = 1;

/// The most bytes of one string (a metadata key or value, a model id).
const MAX_STRING_BYTES: usize = 64 << 10;

/// The most ticks kept while waiting for their run's setup (a recorder that joined late asks
/// the world for it; the ticks that came meanwhile wait here).
pub const MAX_WAITING_TICKS: usize = 400;

/// What a recorder needs before a run's first tick.
#[derive(Debug, Clone, PartialEq)]
pub struct LiveSetup {
    /// The run's index within its scenario.
    pub run_index: u64,
    /// Its position among the launch's runs (0 for the first).
    pub nth: u32,
    /// How many runs the launch plays.
    pub runs: u32,
    /// The team.
    pub team: TeamSetup,
    /// The run's desired distance d* \[m\].
    pub d_star: f64,
    /// The run's metadata record (`formation.run`), with the models' hashes.
    pub metadata: BTreeMap<String, String>,
}

impl LiveSetup {
    /// The live setup of `setup`, the `nth` of `runs` runs, with its metadata as the world's own
    /// recording writes it (the models hashed here; `recording` names the file in errors).
    pub fn for_run(
        setup: &RecordingSetup,
        nth: usize,
        runs: usize,
        recording: &Path,
    ) -> Result<LiveSetup, RecordError> {
        let (metadata, _) = setup.metadata_with_models(recording)?;
        Ok(LiveSetup {
            run_index: setup.run_index as u64,
            nth: u32::try_from(nth).unwrap_or(u32::MAX),
            runs: u32::try_from(runs).unwrap_or(u32::MAX),
            team: setup.team.clone(),
            d_star: setup.d_star,
            metadata,
        })
    }
}

/// One message from the world to a remote recorder.
#[derive(Debug, Clone, PartialEq)]
pub enum LiveMessage {
    /// A run begins.
    Setup(LiveSetup),
    /// One tick of run `run_index`.
    Tick {
        /// The run.
        run_index: u64,
        /// The tick, as the world's own recorder gets it.
        tick: TickRecord,
    },
    /// Run `run_index` ended.
    End {
        /// The run.
        run_index: u64,
        /// The state after its last step (none when the run stopped early).
        last: Option<FinalSample>,
    },
}

/// A live message that could not be read.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// Not a live recording message at all.
    #[error("not a formation live-recording message (it does not begin with FMLV)")]
    Magic,
    /// A version this build does not read.
    #[error(
        "a live-recording message of format version {found}, but this build reads version \
         {FORMAT_VERSION}: use the same formation version as the team"
    )]
    Version {
        /// The version the message says.
        found: u16,
    },
    /// The message is cut short or holds a value out of range.
    #[error("a damaged live-recording message: {0}")]
    Damaged(String),
}

const KIND_SETUP: u8 = 1;
const KIND_TICK: u8 = 2;
const KIND_END: u8 = 3;

/// Little-endian writer of a live message.
struct Writer(Vec<u8>);

impl Writer {
    fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.u64(v.to_bits());
    }
    fn len(&mut self, n: usize) {
        self.u32(u32::try_from(n).unwrap_or(u32::MAX));
    }
    fn str(&mut self, s: &str) {
        let bytes = &s.as_bytes()[..s.len().min(MAX_STRING_BYTES)];
        self.len(bytes.len());
        self.0.extend_from_slice(bytes);
    }
    fn poses(&mut self, poses: &[Pose]) {
        self.len(poses.len());
        for p in poses {
            for v in [p.x, p.y, p.theta] {
                self.f64(v);
            }
        }
    }
}

/// The bytes of `message`.
pub fn encode(message: &LiveMessage) -> Vec<u8> {
    let mut w = Writer(Vec::with_capacity(256));
    w.0.extend_from_slice(&MAGIC);
    w.0.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    match message {
        LiveMessage::Setup(setup) => {
            w.u8(KIND_SETUP);
            encode_setup(&mut w, setup);
        }
        LiveMessage::Tick { run_index, tick } => {
            w.u8(KIND_TICK);
            w.u64(*run_index);
            encode_tick(&mut w, tick);
        }
        LiveMessage::End { run_index, last } => {
            w.u8(KIND_END);
            w.u64(*run_index);
            match last {
                None => w.u8(0),
                Some(last) => {
                    w.u8(1);
                    w.u64(last.tick);
                    w.f64(last.time);
                    w.poses(&last.poses);
                }
            }
        }
    }
    w.0
}

fn encode_setup(w: &mut Writer, setup: &LiveSetup) {
    w.u64(setup.run_index);
    w.u32(setup.nth);
    w.u32(setup.runs);
    w.u64(setup.team.n_robots as u64);
    w.f64(setup.team.max_range);
    w.f64(setup.team.wheel_separation);
    match setup.team.neighbours {
        NeighbourRule::AllPairs => w.u8(0),
        NeighbourRule::Gabriel(rule) => {
            w.u8(1);
            w.f64(rule.sensing_range);
            w.u64(rule.nearest as u64);
            w.f64(rule.threshold);
            w.f64(rule.hysteresis);
        }
    }
    w.f64(setup.d_star);
    w.len(setup.metadata.len());
    for (key, value) in &setup.metadata {
        w.str(key);
        w.str(value);
    }
}

fn encode_tick(w: &mut Writer, tick: &TickRecord) {
    w.u64(tick.tick);
    w.f64(tick.time);
    for v in [tick.goal.phi_star, tick.goal.d_star, tick.goal.v_star] {
        w.f64(v);
    }
    w.poses(&tick.poses);
    w.len(tick.wheel_speeds.len());
    for s in &tick.wheel_speeds {
        w.f64(s.left);
        w.f64(s.right);
    }
    w.len(tick.scans.len());
    for scan in &tick.scans {
        w.len(scan.len());
        for r in scan {
            w.u32(r.to_bits());
        }
    }
    w.len(tick.commands.len());
    for c in &tick.commands {
        w.f64(c.wheels.left);
        w.f64(c.wheels.right);
        w.u8(crate::replay::outcome_code(c.outcome));
        w.u32(c.lag_ticks);
    }
    w.len(tick.model_ids.len());
    for id in &tick.model_ids {
        w.str(id);
    }
}

/// Bounds-checked little-endian reader of a live message.
struct Reader<'a> {
    bytes: &'a [u8],
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], LiveError> {
        if self.bytes.len() < n {
            return Err(LiveError::Damaged(format!("it ends within {what}")));
        }
        let (head, rest) = self.bytes.split_at(n);
        self.bytes = rest;
        Ok(head)
    }
    fn u8(&mut self, what: &str) -> Result<u8, LiveError> {
        Ok(self.take(1, what)?[0])
    }
    fn u32(&mut self, what: &str) -> Result<u32, LiveError> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn u64(&mut self, what: &str) -> Result<u64, LiveError> {
        let b = self.take(8, what)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }
    fn f64(&mut self, what: &str) -> Result<f64, LiveError> {
        Ok(f64::from_bits(self.u64(what)?))
    }
    /// A count of items of at least `item_bytes` bytes each: never more than the bytes left.
    fn len(&mut self, item_bytes: usize, what: &str) -> Result<usize, LiveError> {
        let n = self.u32(what)? as usize;
        if n.saturating_mul(item_bytes.max(1)) > self.bytes.len() {
            return Err(LiveError::Damaged(format!(
                "{what} says {n} items, more than the message holds"
            )));
        }
        Ok(n)
    }
    fn str(&mut self, what: &str) -> Result<String, LiveError> {
        let n = self.len(1, what)?;
        if n > MAX_STRING_BYTES {
            return Err(LiveError::Damaged(format!("{what} is too long")));
        }
        String::from_utf8(self.take(n, what)?.to_vec())
            .map_err(|_| LiveError::Damaged(format!("{what} is not UTF-8")))
    }
    fn poses(&mut self, what: &str) -> Result<Vec<Pose>, LiveError> {
        let n = self.len(24, what)?;
        (0..n)
            .map(|_| Ok(Pose::new(self.f64(what)?, self.f64(what)?, self.f64(what)?)))
            .collect()
    }
}

/// The message in `bytes`.
pub fn decode(bytes: &[u8]) -> Result<LiveMessage, LiveError> {
    let mut r = Reader { bytes };
    if r.take(4, "the header").map_err(|_| LiveError::Magic)? != MAGIC {
        return Err(LiveError::Magic);
    }
    let version = r.take(2, "the header")?;
    let found = u16::from_le_bytes([version[0], version[1]]);
    if found != FORMAT_VERSION {
        return Err(LiveError::Version { found });
    }
    let message = match r.u8("the kind")? {
        KIND_SETUP => LiveMessage::Setup(decode_setup(&mut r)?),
        KIND_TICK => LiveMessage::Tick {
            run_index: r.u64("the run")?,
            tick: decode_tick(&mut r)?,
        },
        KIND_END => {
            let run_index = r.u64("the run")?;
            let last = match r.u8("the end")? {
                0 => None,
                _ => Some(FinalSample {
                    tick: r.u64("the last sample")?,
                    time: r.f64("the last sample")?,
                    poses: r.poses("the last poses")?,
                }),
            };
            LiveMessage::End { run_index, last }
        }
        other => return Err(LiveError::Damaged(format!("unknown kind {other}"))),
    };
    if !r.bytes.is_empty() {
        return Err(LiveError::Damaged(format!(
            "{} bytes follow the message",
            r.bytes.len()
        )));
    }
    Ok(message)
}

fn decode_setup(r: &mut Reader<'_>) -> Result<LiveSetup, LiveError> {
    let run_index = r.u64("the setup")?;
    let nth = r.u32("the setup")?;
    let runs = r.u32("the setup")?;
    let n_robots = usize::try_from(r.u64("the team")?)
        .map_err(|_| LiveError::Damaged("the team size is out of range".into()))?;
    let max_range = r.f64("the team")?;
    let wheel_separation = r.f64("the team")?;
    let neighbours = match r.u8("the neighbour rule")? {
        0 => NeighbourRule::AllPairs,
        1 => NeighbourRule::Gabriel(GabrielRule {
            sensing_range: r.f64("the neighbour rule")?,
            nearest: usize::try_from(r.u64("the neighbour rule")?).unwrap_or(usize::MAX),
            threshold: r.f64("the neighbour rule")?,
            hysteresis: r.f64("the neighbour rule")?,
        }),
        other => {
            return Err(LiveError::Damaged(format!(
                "unknown neighbour rule {other}"
            )));
        }
    };
    if n_robots == 0 || n_robots > 4096 || nth >= runs {
        return Err(LiveError::Damaged(format!(
            "a setup of {n_robots} robots, run {nth} of {runs}"
        )));
    }
    let d_star = r.f64("the setup")?;
    let entries = r.len(8, "the metadata")?;
    let mut metadata = BTreeMap::new();
    for _ in 0..entries {
        let key = r.str("a metadata key")?;
        let value = r.str("a metadata value")?;
        metadata.insert(key, value);
    }
    Ok(LiveSetup {
        run_index,
        nth,
        runs,
        team: TeamSetup {
            n_robots,
            max_range,
            wheel_separation,
            neighbours,
            wheels: formation_proto::WheelLimits::default(),
        },
        d_star,
        metadata,
    })
}

fn outcome_from_code(code: u8) -> Result<TickOutcome, LiveError> {
    TickOutcome::ALL
        .into_iter()
        .find(|&o| crate::replay::outcome_code(o) == code)
        .ok_or_else(|| LiveError::Damaged(format!("unknown outcome code {code}")))
}

fn decode_tick(r: &mut Reader<'_>) -> Result<TickRecord, LiveError> {
    let tick = r.u64("the tick")?;
    let time = r.f64("the tick")?;
    let goal = Goal {
        phi_star: r.f64("the goal")?,
        d_star: r.f64("the goal")?,
        v_star: r.f64("the goal")?,
    };
    let poses = r.poses("the poses")?;
    let n = r.len(16, "the wheel speeds")?;
    let wheel_speeds = (0..n)
        .map(|_| {
            Ok(WheelCmd {
                left: r.f64("the wheel speeds")?,
                right: r.f64("the wheel speeds")?,
            })
        })
        .collect::<Result<Vec<_>, LiveError>>()?;
    let n = r.len(4, "the scans")?;
    let mut scans = Vec::with_capacity(n);
    for _ in 0..n {
        let beams = r.len(4, "a scan")?;
        let scan = (0..beams)
            .map(|_| Ok(f32::from_bits(r.u32("a scan")?)))
            .collect::<Result<Vec<_>, LiveError>>()?;
        scans.push(scan);
    }
    let n = r.len(21, "the commands")?;
    let commands = (0..n)
        .map(|_| {
            Ok(SentCommand {
                wheels: WheelCmd {
                    left: r.f64("a command")?,
                    right: r.f64("a command")?,
                },
                outcome: outcome_from_code(r.u8("a command")?)?,
                lag_ticks: r.u32("a command")?,
            })
        })
        .collect::<Result<Vec<_>, LiveError>>()?;
    let n = r.len(4, "the model ids")?;
    let model_ids = (0..n)
        .map(|_| r.str("a model id"))
        .collect::<Result<Vec<_>, LiveError>>()?;
    Ok(TickRecord {
        tick,
        time,
        goal,
        poses,
        wheel_speeds,
        scans,
        commands,
        model_ids,
    })
}

/// What the recording of one run became.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LiveRunDone {
    /// The run.
    pub run_index: u64,
    /// The file's summary.
    pub summary: RecordingSummary,
    /// The first tick recorded (0 unless the recorder joined late; none when no tick came).
    pub first_tick: Option<u64>,
    /// Ticks recorded.
    pub ticks: u64,
    /// Whether the run played to its end (the world sent its last state).
    pub ended: bool,
    /// Whether it was the launch's last run.
    pub last_run: bool,
}

/// The run being recorded.
#[derive(Debug)]
struct LiveRun {
    setup: LiveSetup,
    file: Option<RecordingFile>,
    first_tick: Option<u64>,
    ticks: u64,
}

/// A recorder's side: live messages in, recording files out (see the module docs).
#[derive(Debug)]
pub struct LiveRecording {
    target: RecordTarget,
    /// How the recorder is named in the metadata (`live.recorded_by`).
    recorded_by: String,
    run: Option<LiveRun>,
    /// Ticks that came before their run's setup.
    waiting: Vec<(u64, TickRecord)>,
}

impl LiveRecording {
    /// Records into `out` (with several runs, run `N` into `<stem>-run-NNNN.mcap` beside it, as
    /// `--record` names them); `recorded_by` goes into each file's metadata.
    pub fn new(out: &Path, recorded_by: &str) -> LiveRecording {
        LiveRecording {
            target: RecordTarget::File(out.to_path_buf()),
            recorded_by: recorded_by.to_owned(),
            run: None,
            waiting: Vec::new(),
        }
    }

    /// Whether a run's setup has come (a recorder that joined late asks for it until then).
    pub fn has_setup(&self) -> bool {
        self.run.is_some()
    }

    /// The file of the run being recorded, when there is one.
    pub fn current_path(&self) -> Option<PathBuf> {
        let run = self.run.as_ref()?;
        self.path_of(&run.setup)
    }

    fn path_of(&self, setup: &LiveSetup) -> Option<PathBuf> {
        self.target.path_for(
            usize::try_from(setup.run_index).unwrap_or(usize::MAX),
            0,
            setup.runs as usize,
        )
    }

    /// Takes one message; returns the run it finished, if any (a new run's setup finishes a
    /// run whose end never came).
    pub fn take(&mut self, message: LiveMessage) -> Result<Option<LiveRunDone>, RecordError> {
        match message {
            LiveMessage::Setup(setup) => self.begin(setup),
            LiveMessage::Tick { run_index, tick } => {
                match &self.run {
                    Some(run) if run.setup.run_index == run_index => self.write(tick)?,
                    _ => {
                        if self.waiting.len() >= MAX_WAITING_TICKS {
                            self.waiting.remove(0);
                        }
                        self.waiting.push((run_index, tick));
                    }
                }
                Ok(None)
            }
            LiveMessage::End { run_index, last } => match &self.run {
                Some(run) if run.setup.run_index == run_index => self.end(last.as_ref(), true),
                _ => Ok(None),
            },
        }
    }

    /// Starts run `setup` (a repeat of the current run's setup is ignored), finishing a
    /// previous run whose end never came, and writes the ticks of it that were waiting.
    fn begin(&mut self, setup: LiveSetup) -> Result<Option<LiveRunDone>, RecordError> {
        if self
            .run
            .as_ref()
            .is_some_and(|r| r.setup.run_index == setup.run_index)
        {
            return Ok(None);
        }
        let previous = self.end(None, false)?;
        let run_index = setup.run_index;
        self.run = Some(LiveRun {
            setup,
            file: None,
            first_tick: None,
            ticks: 0,
        });
        let waiting = std::mem::take(&mut self.waiting);
        for (_, tick) in waiting.into_iter().filter(|(run, _)| *run == run_index) {
            self.write(tick)?;
        }
        Ok(previous)
    }

    /// Writes one tick of the current run, creating its file at its first.
    fn write(&mut self, tick: TickRecord) -> Result<(), RecordError> {
        let path = self.current_path();
        let recorded_by = self.recorded_by.clone();
        let Some(run) = &mut self.run else {
            return Ok(());
        };
        if run
            .first_tick
            .is_some_and(|first| tick.tick < first + run.ticks)
        {
            return Ok(()); // a tick already written (the query's and the channel's copies)
        }
        if run.file.is_none() {
            run.first_tick = Some(tick.tick);
            run.file = Some(create_file(path, &run.setup, tick.tick, &recorded_by)?);
        }
        if let Some(file) = &mut run.file {
            file.write_tick(&tick)?;
            run.ticks += 1;
        }
        Ok(())
    }

    /// Finishes the current run's file (with `last`, the state after its last step, when
    /// given); `ended`: the world said the run ended.
    fn end(
        &mut self,
        last: Option<&FinalSample>,
        ended: bool,
    ) -> Result<Option<LiveRunDone>, RecordError> {
        let path = self.current_path();
        let Some(mut run) = self.run.take() else {
            return Ok(None);
        };
        let file = match run.file.take() {
            Some(file) => file,
            None => {
                let first = last.map_or(0, |l| l.tick);
                create_file(path, &run.setup, first, &self.recorded_by)?
            }
        };
        let summary = file.finish(last)?;
        Ok(Some(LiveRunDone {
            run_index: run.setup.run_index,
            summary,
            first_tick: run.first_tick,
            ticks: run.ticks,
            ended,
            last_run: run.setup.nth + 1 >= run.setup.runs,
        }))
    }

    /// Finishes the run under way with what arrived (the link was lost, or the recorder was
    /// stopped).
    pub fn abandon(&mut self) -> Result<Option<LiveRunDone>, RecordError> {
        self.end(None, false)
    }
}

/// Creates the file of `setup`'s run at `path`, its first recorded tick being `first_tick`.
fn create_file(
    path: Option<PathBuf>,
    setup: &LiveSetup,
    first_tick: u64,
    recorded_by: &str,
) -> Result<RecordingFile, RecordError> {
    let path = path.unwrap_or_else(|| PathBuf::from("recording.mcap"));
    let mut metadata = setup.metadata.clone();
    for value in metadata.values_mut() {
        // A model the world stores as an attachment stays on the world's host.
        if value.starts_with("attachment ") {
            *value = format!("{NOT_STORED_PREFIX}{value})");
        }
    }
    metadata.insert("live.recorded_by".into(), recorded_by.to_owned());
    metadata.insert("live.first_tick".into(), first_tick.to_string());
    metadata.insert(
        "live.complete_from_start".into(),
        (first_tick == 0).to_string(),
    );
    RecordingFile::create_with_metadata(&path, setup.team.clone(), setup.d_star, metadata)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setup(run_index: u64, nth: u32, runs: u32) -> LiveSetup {
        LiveSetup {
            run_index,
            nth,
            runs,
            team: TeamSetup {
                n_robots: 2,
                max_range: 4.0,
                wheel_separation: 0.2,
                neighbours: NeighbourRule::Gabriel(GabrielRule {
                    sensing_range: 4.0,
                    nearest: 2,
                    threshold: 1.0,
                    hysteresis: 0.1,
                }),
                wheels: formation_proto::WheelLimits::default(),
            },
            d_star: 1.5,
            metadata: BTreeMap::from([
                ("scenario".to_owned(), "case1".to_owned()),
                (
                    "model.0.stored".to_owned(),
                    "attachment models/ab.onnx".to_owned(),
                ),
            ]),
        }
    }

    fn tick(k: u64) -> TickRecord {
        TickRecord {
            tick: k,
            time: k as f64 * 0.05,
            goal: Goal::new(0.1, 1.5, 0.2),
            poses: vec![Pose::new(1.0, -2.0, 0.3); 2],
            wheel_speeds: vec![WheelCmd::default(); 2],
            scans: vec![vec![1.0, f32::INFINITY, 3.5], vec![2.0; 3]],
            commands: vec![
                SentCommand {
                    wheels: WheelCmd::new(f64::NAN, 0.5),
                    outcome: TickOutcome::NonFinite,
                    lag_ticks: 3,
                },
                SentCommand::in_process(WheelCmd::new(0.1, 0.2)),
            ],
            model_ids: vec!["m0".into(), "m1".into()],
        }
    }

    #[test]
    fn every_message_round_trips_bit_for_bit_and_damage_is_named() {
        let messages = [
            LiveMessage::Setup(setup(4, 1, 3)),
            LiveMessage::Setup(LiveSetup {
                team: TeamSetup {
                    neighbours: NeighbourRule::AllPairs,
                    wheels: formation_proto::WheelLimits::default(),
                    ..setup(0, 0, 1).team
                },
                ..setup(0, 0, 1)
            }),
            LiveMessage::Tick {
                run_index: 4,
                tick: tick(7),
            },
            LiveMessage::End {
                run_index: 4,
                last: Some(FinalSample {
                    tick: 9,
                    time: 0.45,
                    poses: tick(0).poses,
                }),
            },
            LiveMessage::End {
                run_index: 4,
                last: None,
            },
        ];
        for message in messages {
            let bytes = encode(&message);
            let back = decode(&bytes).unwrap();
            // NaN != NaN: compare the encodings, which hold every float's bits.
            assert_eq!(encode(&back), bytes, "{message:?}");
            for cut in [0, 5, bytes.len() / 2, bytes.len() - 1] {
                assert!(decode(&bytes[..cut]).is_err(), "cut at {cut}");
            }
        }
        let mut future = encode(&LiveMessage::End {
            run_index: 0,
            last: None,
        });
        future[4] = 9;
        let text = decode(&future).unwrap_err().to_string();
        assert!(text.contains("version 9") && text.contains("same formation version"));
        assert!(matches!(decode(b"nope"), Err(LiveError::Magic)));
        // A count larger than the message is refused before anything is allocated.
        let mut huge = encode(&LiveMessage::Tick {
            run_index: 0,
            tick: tick(0),
        });
        let poses_count = 4 + 2 + 1 + 8 + 8 + 8 + 24;
        huge[poses_count..poses_count + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(decode(&huge).unwrap_err().to_string().contains("more than"));
    }

    #[test]
    fn a_late_recorder_records_from_the_tick_it_joined_and_says_so() {
        let dir = std::env::temp_dir().join(format!("formation-live-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("live.mcap");
        let mut live = LiveRecording::new(&out, "test");
        // Ticks 5 and 6 come before the setup (asked for, since the recorder joined late).
        for k in [5, 6] {
            let t = LiveMessage::Tick {
                run_index: 2,
                tick: tick(k),
            };
            assert_eq!(live.take(t).unwrap(), None);
        }
        assert!(!live.has_setup());
        assert_eq!(live.take(LiveMessage::Setup(setup(2, 0, 1))).unwrap(), None);
        // The setup again (from the channel) and tick 6 again change nothing.
        assert_eq!(live.take(LiveMessage::Setup(setup(2, 0, 1))).unwrap(), None);
        for k in [6, 7] {
            let t = LiveMessage::Tick {
                run_index: 2,
                tick: tick(k),
            };
            live.take(t).unwrap();
        }
        let done = live
            .take(LiveMessage::End {
                run_index: 2,
                last: None,
            })
            .unwrap()
            .expect("the run is done");
        assert_eq!(done.first_tick, Some(5));
        assert_eq!(done.ticks, 3);
        assert!(done.ended && done.last_run);
        assert_eq!(done.summary.path, out);
        let bytes = std::fs::read(&out).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.contains("live.first_tick") && text.contains("not stored (recorded live"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
