//! The messages exchanged between the world process and the robot-agent processes, whatever
//! carries them, and the names of their channels.
//!
//! Every message is a fixed-size `#[repr(C)]` value. Over iceoryx2 it is placed in shared memory
//! as it is, so nothing is serialised: with this crate's `iceoryx2` feature each message derives
//! iceoryx2's `ZeroCopySend` under a versioned type name. The iceoryx2 service names, limits and
//! namespaces of a run are the runtime's (`formation_transport_iceoryx2::naming`); the launch secret
//! that proves an agent's [`HelloMsg`] is the runtime's `auth` module. Wire structs are
//! deliberately dumb (plain numbers and fixed byte arrays); each has a typed Rust view
//! ([`ControlRequest`], [`AgentStatus`], [`CmdStatus`]) and a checked constructor, so a malformed
//! message turns into a [`WireError`] instead of a panic.
//!
//! Per robot there is a *lobby* ([`LobbyChannel`]): a candidate agent says [`HelloMsg`] and the
//! world answers [`WelcomeMsg`]. Per accepted agent (an *incarnation*, named by the agent's nonce)
//! there are four channels ([`RobotChannel`]): [`ScanMsg`] (world → agent), [`CmdMsg`] (agent →
//! world), [`ControlMsg`] (world → agent) and [`StatusMsg`] (agent → world). Per run there is a
//! swap channel ([`SwapChannel`]): [`SwapRequestMsg`] from `formation swap` and [`SwapReplyMsg`]
//! back.
//!
//! Transports that carry bytes rather than shared memory (Zenoh, between hosts) send each message's
//! own bytes: every wire struct is [`bytemuck::Pod`] (no padding, checked when it compiles), so
//! [`message_bytes`] views it and [`message_from_bytes`] takes it back, refusing a payload of the
//! wrong size. The bytes are in the host's byte order: every host of one run must share it (every
//! supported target is little-endian).

use std::path::PathBuf;
use std::time::{SystemTime, UNIX_EPOCH};

#[cfg(feature = "iceoryx2")]
use iceoryx2::prelude::ZeroCopySend;

use crate::types::{Goal, LidarSpec, WheelCmd, WheelLimits};

/// Most LIDAR beams a [`ScanMsg`] can carry (the paper's sensor: 900 beams over 360 degrees).
pub const MAX_BEAMS: usize = 900;
/// Bytes of an agent's proof of the launch secret in a [`HelloMsg`]: one HMAC-SHA256.
pub const PROOF_LEN: usize = 32;
/// Bytes of a model id on the wire (UTF-8, zero padded).
pub const MODEL_ID_LEN: usize = 64;
/// Bytes of a model path in a swap request (UTF-8, zero padded).
pub const MODEL_PATH_LEN: usize = 512;
/// Bytes of a refusal reason in a status message (UTF-8, zero padded; a longer reason is cut at a
/// word boundary and ends in `…`).
pub const REASON_LEN: usize = 1024;
/// Longest accepted run id.
pub const MAX_RUN_ID_LEN: usize = 24;

/// Why a message, a name or a namespace could not be built or read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// A run id with characters other than ASCII letters, digits, `-` and `_`, or of bad length.
    #[error(
        "run id {run:?} is not valid: use 1 to {MAX_RUN_ID_LEN} ASCII letters, digits, '-' or '_'"
    )]
    InvalidRunId {
        /// The rejected id.
        run: String,
    },
    /// A scan longer than a [`ScanMsg`] can carry.
    #[error("a scan of {beams} beams does not fit the wire message (at most {MAX_BEAMS} beams)")]
    TooManyBeams {
        /// Beams in the scan.
        beams: usize,
    },
    /// A text field (model id, model path) longer than its fixed wire field.
    #[error("{field} is {len} bytes long; the wire field holds at most {max} bytes")]
    TextTooLong {
        /// Which field.
        field: &'static str,
        /// Its length in bytes.
        len: usize,
        /// The field's capacity.
        max: usize,
    },
    /// A message whose kind code is not known to this version.
    #[error("unknown {message} kind {kind}: world and agent binaries are from different builds")]
    UnknownKind {
        /// Which message type.
        message: &'static str,
        /// The code received.
        kind: u32,
    },
    /// A message field that does not hold a valid value.
    #[error("malformed {message}: {reason}")]
    Malformed {
        /// Which message type.
        message: &'static str,
        /// What is wrong.
        reason: String,
    },
}

/// The bytes of a wire message, as a transport between hosts sends them.
pub fn message_bytes<T: bytemuck::Pod>(msg: &T) -> &[u8] {
    bytemuck::bytes_of(msg)
}

/// A wire message back from the bytes [`message_bytes`] gave; a payload of another size (a
/// different build, a stray publisher) is [`WireError::Malformed`].
pub fn message_from_bytes<T: bytemuck::Pod>(
    message: &'static str,
    bytes: &[u8],
) -> Result<T, WireError> {
    bytemuck::try_pod_read_unaligned(bytes).map_err(|_| WireError::Malformed {
        message,
        reason: format!(
            "{} bytes arrived, the message has {}: world and agent binaries are from different \
             builds, or another process publishes on this key",
            bytes.len(),
            std::mem::size_of::<T>()
        ),
    })
}

// ---------------------------------------------------------------------------------------------
// Run ids, service names, namespaces
// ---------------------------------------------------------------------------------------------

/// The id of one launch of the runtime. It namespaces service names and iceoryx2 files.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct RunId(String);

impl RunId {
    /// Validates an id: 1 to [`MAX_RUN_ID_LEN`] ASCII letters, digits, `-` or `_`.
    pub fn new(id: &str) -> Result<RunId, WireError> {
        let ok = !id.is_empty()
            && id.len() <= MAX_RUN_ID_LEN
            && id
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
        if ok {
            Ok(RunId(id.to_owned()))
        } else {
            Err(WireError::InvalidRunId { run: id.to_owned() })
        }
    }

    /// A fresh id, unique on this machine: the process id and the wall-clock nanoseconds, in base 36.
    pub fn generate() -> RunId {
        let nanos = wall_clock_ns();
        RunId(format!(
            "{}{}",
            base36(u64::from(std::process::id())),
            base36(nanos % (36u64.pow(8)))
        ))
    }

    /// The id as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl std::fmt::Display for RunId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

fn base36(mut n: u64) -> String {
    const DIGITS: &[u8; 36] = b"0123456789abcdefghijklmnopqrstuvwxyz";
    let mut out = Vec::new();
    loop {
        out.push(DIGITS[(n % 36) as usize]);
        n /= 36;
        if n == 0 {
            break;
        }
    }
    out.reverse();
    String::from_utf8(out).unwrap_or_default()
}

/// The channels of one robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RobotChannel {
    /// World → agent: the robot's own scan, heading and goal ([`ScanMsg`]).
    Scan,
    /// Agent → world: the robot's wheel command ([`CmdMsg`]).
    Cmd,
    /// World → agent: episode begin, shutdown, model swap ([`ControlMsg`]).
    Control,
    /// Agent → world: hello, ready, refusals, swap acknowledgements ([`StatusMsg`]).
    Status,
}

impl RobotChannel {
    /// Every channel.
    pub const ALL: [RobotChannel; 4] = [
        RobotChannel::Scan,
        RobotChannel::Cmd,
        RobotChannel::Control,
        RobotChannel::Status,
    ];

    /// The last segment of the service name.
    pub fn as_str(&self) -> &'static str {
        match self {
            RobotChannel::Scan => "scan",
            RobotChannel::Cmd => "cmd",
            RobotChannel::Control => "control",
            RobotChannel::Status => "status",
        }
    }
}

/// The two services of a robot's lobby.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LobbyChannel {
    /// Candidate agents → world ([`HelloMsg`]); paired with an event service.
    Hello,
    /// World → candidate agents ([`WelcomeMsg`]); polled, no event.
    Welcome,
}

/// The two services of a run's swap channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwapChannel {
    /// `formation swap` → world ([`SwapRequestMsg`]).
    Request,
    /// World → `formation swap` ([`SwapReplyMsg`]).
    Reply,
}

/// Nanoseconds since the Unix epoch on the system clock: the one clock every process of a run
/// shares, used only to measure one-way latencies between processes.
pub fn wall_clock_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
        .unwrap_or(0)
}

/// `formation/<run>/robot/<robot>/<incarnation>/<channel>`, the incarnation in 16 hex digits: the
/// name of both the publish-subscribe service and its paired event service of one accepted agent.
pub fn robot_service_name(
    run: &RunId,
    robot: usize,
    incarnation: u64,
    channel: RobotChannel,
) -> String {
    format!(
        "formation/{run}/robot/{robot}/{incarnation:016x}/{}",
        channel.as_str()
    )
}

/// `formation/<run>/robot/<robot>/hello` or `.../welcome`.
pub fn lobby_service_name(run: &RunId, robot: usize, channel: LobbyChannel) -> String {
    match channel {
        LobbyChannel::Hello => format!("formation/{run}/robot/{robot}/hello"),
        LobbyChannel::Welcome => format!("formation/{run}/robot/{robot}/welcome"),
    }
}

/// `formation/<run>/swap/request` or `formation/<run>/swap/reply`: the name of both the
/// publish-subscribe service and its paired event service.
pub fn swap_service_name(run: &RunId, channel: SwapChannel) -> String {
    match channel {
        SwapChannel::Request => format!("formation/{run}/swap/request"),
        SwapChannel::Reply => format!("formation/{run}/swap/reply"),
    }
}

// ---------------------------------------------------------------------------------------------
// Fixed text fields
// ---------------------------------------------------------------------------------------------

fn encode_text<const N: usize>(field: &'static str, text: &str) -> Result<[u8; N], WireError> {
    if text.len() > N {
        return Err(WireError::TextTooLong {
            field,
            len: text.len(),
            max: N,
        });
    }
    let mut out = [0u8; N];
    out[..text.len()].copy_from_slice(text.as_bytes());
    Ok(out)
}

/// Like [`encode_text`] but for human messages: an over-long text is cut at the last word
/// boundary that leaves room for a closing `…`, so a reader sees that something was cut and
/// never half a word.
fn encode_text_lossy<const N: usize>(text: &str) -> [u8; N] {
    const ELLIPSIS: &str = " …";
    let mut out = [0u8; N];
    if text.len() <= N {
        out[..text.len()].copy_from_slice(text.as_bytes());
        return out;
    }
    let mut end = N.saturating_sub(ELLIPSIS.len());
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    let cut = text[..end]
        .rfind(char::is_whitespace)
        .filter(|&at| at > end / 2)
        .unwrap_or(end);
    let kept = text[..cut].trim_end();
    out[..kept.len()].copy_from_slice(kept.as_bytes());
    out[kept.len()..kept.len() + ELLIPSIS.len()].copy_from_slice(ELLIPSIS.as_bytes());
    out
}

fn decode_text<'a>(message: &'static str, bytes: &'a [u8]) -> Result<&'a str, WireError> {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    std::str::from_utf8(&bytes[..end]).map_err(|e| WireError::Malformed {
        message,
        reason: format!("text field is not UTF-8 ({e})"),
    })
}

// ---------------------------------------------------------------------------------------------
// Lobby: candidate agent -> world, and the world's answer
// ---------------------------------------------------------------------------------------------

/// An agent's request to drive one robot: its pid, a fresh nonce (which also names the
/// incarnation's services if the world accepts) and its proof of the launch secret.
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[cfg_attr(
    feature = "iceoryx2",
    derive(ZeroCopySend),
    type_name("formation.HelloMsg.v1")
)]
#[repr(C)]
pub struct HelloMsg {
    /// The candidate's process id.
    pub pid: u32,
    /// Keeps the layout explicit; always 0.
    pub reserved: u32,
    /// A fresh random number, never used twice.
    pub nonce: u64,
    /// the runtime's `LaunchSecret::prove` over the run, the robot, `pid` and `nonce`.
    pub proof: [u8; PROOF_LEN],
}

/// The world's answer to one [`HelloMsg`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Welcome {
    /// The incarnation's services exist now: open them and drive.
    Accepted,
    /// Refused; the reason is phrased for the user.
    Refused(String),
}

/// The wire form of a [`Welcome`], tagged with the nonce of the hello it answers.
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[cfg_attr(
    feature = "iceoryx2",
    derive(ZeroCopySend),
    type_name("formation.WelcomeMsg.v1")
)]
#[repr(C)]
pub struct WelcomeMsg {
    /// The nonce of the hello this answers.
    pub nonce: u64,
    /// 1 accepted, 2 refused.
    pub kind: u32,
    /// Keeps the layout explicit; always 0.
    pub reserved: u32,
    /// Why (refused), UTF-8, zero padded, possibly cut.
    pub reason: [u8; REASON_LEN],
}

const WELCOME_ACCEPTED: u32 = 1;
const WELCOME_REFUSED: u32 = 2;

impl WelcomeMsg {
    /// Encodes the answer to the hello with `nonce`.
    pub fn encode(nonce: u64, welcome: &Welcome) -> WelcomeMsg {
        let (kind, reason) = match welcome {
            Welcome::Accepted => (WELCOME_ACCEPTED, [0; REASON_LEN]),
            Welcome::Refused(reason) => (WELCOME_REFUSED, encode_text_lossy(reason)),
        };
        WelcomeMsg {
            nonce,
            kind,
            reserved: 0,
            reason,
        }
    }

    /// Decodes the answer.
    pub fn decode(&self) -> Result<Welcome, WireError> {
        match self.kind {
            WELCOME_ACCEPTED => Ok(Welcome::Accepted),
            WELCOME_REFUSED => Ok(Welcome::Refused(
                decode_text("welcome", &self.reason)?.to_owned(),
            )),
            kind => Err(WireError::UnknownKind {
                message: "welcome",
                kind,
            }),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Scan: world -> agent
// ---------------------------------------------------------------------------------------------

/// One robot's observation at one tick: its own scan, its own compass heading and the goal.
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[cfg_attr(
    feature = "iceoryx2",
    derive(ZeroCopySend),
    type_name("formation.ScanMsg.v1")
)]
#[repr(C)]
pub struct ScanMsg {
    /// Episode generation: increases with every episode the world begins; stale messages of an
    /// earlier episode are recognised by it.
    pub generation: u64,
    /// Tick index `k` within the episode.
    pub tick: u64,
    /// Simulated time `k dt` \[s\].
    pub sim_time: f64,
    /// The robot's own heading \[rad\] (its compass).
    pub heading: f64,
    /// Desired heading phi* at this tick \[rad\].
    pub phi_star: f64,
    /// Desired pairwise distance d* \[m\].
    pub d_star: f64,
    /// Desired speed v* \[m/s\].
    pub v_star: f64,
    /// [`wall_clock_ns`] when the world published this scan.
    pub published_wall_ns: u64,
    /// Valid entries of `ranges`.
    pub n_beams: u32,
    /// Keeps the layout explicit; always 0.
    pub reserved: u32,
    /// Ranges \[m\], beam `k` at body-frame bearing `2 pi k / n_beams`; entries past `n_beams` are 0.
    pub ranges: [f32; MAX_BEAMS],
}

impl ScanMsg {
    /// A scan message. Fails when `ranges` has more than [`MAX_BEAMS`] entries.
    pub fn new(
        generation: u64,
        tick: u64,
        sim_time: f64,
        heading: f64,
        goal: &Goal,
        ranges: &[f32],
    ) -> Result<ScanMsg, WireError> {
        if ranges.len() > MAX_BEAMS {
            return Err(WireError::TooManyBeams {
                beams: ranges.len(),
            });
        }
        let mut fixed = [0.0f32; MAX_BEAMS];
        fixed[..ranges.len()].copy_from_slice(ranges);
        Ok(ScanMsg {
            generation,
            tick,
            sim_time,
            heading,
            phi_star: goal.phi_star,
            d_star: goal.d_star,
            v_star: goal.v_star,
            published_wall_ns: wall_clock_ns(),
            n_beams: ranges.len() as u32,
            reserved: 0,
            ranges: fixed,
        })
    }

    /// The valid ranges. Fails on an `n_beams` beyond [`MAX_BEAMS`].
    pub fn ranges(&self) -> Result<&[f32], WireError> {
        let n = self.n_beams as usize;
        self.ranges.get(..n).ok_or_else(|| WireError::Malformed {
            message: "scan",
            reason: format!("n_beams {n} exceeds the {MAX_BEAMS} the message holds"),
        })
    }

    /// The goal carried by the scan.
    pub fn goal(&self) -> Goal {
        Goal {
            phi_star: self.phi_star,
            d_star: self.d_star,
            v_star: self.v_star,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Command: agent -> world
// ---------------------------------------------------------------------------------------------

/// Status bits an agent attaches to a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CmdStatus(pub u32);

impl CmdStatus {
    /// A normal decision.
    pub const OK: CmdStatus = CmdStatus(0);
    /// The agent could not decide (bad scan or goal, policy failure) and asks for a brake.
    pub const DECISION_FAILED: CmdStatus = CmdStatus(1);
    /// A fault-injection mode altered this command (testing only).
    pub const FAULT_INJECTED: CmdStatus = CmdStatus(1 << 1);
    /// A new model took over at this tick.
    pub const MODEL_SWAPPED: CmdStatus = CmdStatus(1 << 2);

    /// True when every bit of `other` is set.
    pub fn contains(self, other: CmdStatus) -> bool {
        self.0 & other.0 == other.0
    }

    /// Both sets of bits.
    pub fn with(self, other: CmdStatus) -> CmdStatus {
        CmdStatus(self.0 | other.0)
    }
}

/// One robot's wheel command for one tick, with the agent's own timings.
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[cfg_attr(
    feature = "iceoryx2",
    derive(ZeroCopySend),
    type_name("formation.CmdMsg.v1")
)]
#[repr(C)]
pub struct CmdMsg {
    /// Episode generation of the scan this answers.
    pub generation: u64,
    /// Tick of the scan this answers.
    pub tick: u64,
    /// Left wheel rim speed \[m/s\].
    pub left: f64,
    /// Right wheel rim speed \[m/s\].
    pub right: f64,
    /// [`wall_clock_ns`] when the agent took the scan from its subscriber.
    pub received_wall_ns: u64,
    /// Time spent rendering the occupancy image \[ns\].
    pub occupancy_ns: u64,
    /// Time spent in the policy, including speed scaling \[ns\].
    pub inference_ns: u64,
    /// [`wall_clock_ns`] just before the agent published this command.
    pub published_wall_ns: u64,
    /// [`CmdStatus`] bits.
    pub status: u32,
    /// Keeps the layout explicit; always 0.
    pub reserved: u32,
    /// Id of the model that decided (UTF-8, zero padded).
    pub model_id: [u8; MODEL_ID_LEN],
}

/// Timings an agent measured for one command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AgentTimings {
    /// [`wall_clock_ns`] when the scan was taken from the subscriber.
    pub received_wall_ns: u64,
    /// Occupancy rendering \[ns\].
    pub occupancy_ns: u64,
    /// Policy inference \[ns\].
    pub inference_ns: u64,
}

impl CmdMsg {
    /// A command message; `published_wall_ns` is stamped now. Fails on a model id longer than
    /// [`MODEL_ID_LEN`] bytes.
    pub fn new(
        generation: u64,
        tick: u64,
        cmd: WheelCmd,
        model_id: &str,
        timings: AgentTimings,
        status: CmdStatus,
    ) -> Result<CmdMsg, WireError> {
        Ok(CmdMsg {
            generation,
            tick,
            left: cmd.left,
            right: cmd.right,
            received_wall_ns: timings.received_wall_ns,
            occupancy_ns: timings.occupancy_ns,
            inference_ns: timings.inference_ns,
            published_wall_ns: wall_clock_ns(),
            status: status.0,
            reserved: 0,
            model_id: encode_text("model id", model_id)?,
        })
    }

    /// The wheel command.
    pub fn wheels(&self) -> WheelCmd {
        WheelCmd {
            left: self.left,
            right: self.right,
        }
    }

    /// The status bits.
    pub fn status(&self) -> CmdStatus {
        CmdStatus(self.status)
    }

    /// The model id.
    pub fn model_id(&self) -> Result<&str, WireError> {
        decode_text("command", &self.model_id)
    }

    /// The agent's timings.
    pub fn timings(&self) -> AgentTimings {
        AgentTimings {
            received_wall_ns: self.received_wall_ns,
            occupancy_ns: self.occupancy_ns,
            inference_ns: self.inference_ns,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Control: world -> agent
// ---------------------------------------------------------------------------------------------

/// What the world asks of an agent, outside the per-tick exchange.
#[derive(Debug, Clone, PartialEq)]
pub enum ControlRequest {
    /// A new episode starts: answer [`AgentStatus::Ready`] (or [`AgentStatus::Refused`] when the
    /// model does not fit this sensor) with the same generation, then expect its scans.
    BeginEpisode {
        /// The episode's generation.
        generation: u64,
        /// The robot's LIDAR settings this episode.
        lidar: LidarSpec,
        /// The robot's wheel limits this episode, within which a policy that answers a
        /// formation velocity turns it into wheel speeds: a real robot knows its own wheels.
        wheels: WheelLimits,
    },
    /// Load another model off the hot path and let it drive from the first tick `>= at_tick`.
    SwapModel {
        /// Request id echoed in the acknowledgement.
        request_id: u64,
        /// First tick the new model may drive.
        at_tick: u64,
        /// The ONNX model file.
        path: PathBuf,
    },
    /// The run is over: exit cleanly.
    Shutdown,
}

/// The wire form of a [`ControlRequest`].
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[cfg_attr(
    feature = "iceoryx2",
    derive(ZeroCopySend),
    type_name("formation.ControlMsg.v2")
)]
#[repr(C)]
pub struct ControlMsg {
    /// 1 begin episode, 2 swap model, 3 shutdown.
    pub kind: u32,
    /// LIDAR beams (begin episode).
    pub beams: u32,
    /// Episode generation (begin episode).
    pub generation: u64,
    /// LIDAR maximum range \[m\] (begin episode).
    pub max_range: f64,
    /// The robot's largest wheel speed \[m/s\], 0 for not told (begin episode). Worlds before
    /// 2026-12-07 wrote 0 here (the slot held the world's LIDAR noise, unused by agents), and
    /// agents before then ignore it, so the layout and the type name stay.
    pub max_wheel_speed: f64,
    /// The robot's wheel acceleration limit \[m/s²\], 0 for none (begin episode).
    pub max_wheel_accel: f64,
    /// Request id (swap model).
    pub request_id: u64,
    /// First tick the new model may drive (swap model).
    pub at_tick: u64,
    /// Model path, UTF-8, zero padded (swap model).
    pub path: [u8; MODEL_PATH_LEN],
}

const CONTROL_BEGIN: u32 = 1;
/// The names of [`ControlMsg`]'s two wheel limits in its errors.
const WHEEL_SPEED_LIMIT: &str = "wheel speed limit";
const WHEEL_ACCEL_LIMIT: &str = "wheel acceleration limit";

/// A limit on the wire: 0 for none, else the finite number > 0 it is.
fn encode_limit(what: &str, limit: Option<f64>) -> Result<f64, WireError> {
    match limit {
        None => Ok(0.0),
        Some(value) if value.is_finite() && value > 0.0 => Ok(value),
        Some(value) => Err(WireError::Malformed {
            message: "control",
            reason: format!("{what} {value} is not a finite number > 0"),
        }),
    }
}

/// A limit off the wire ([`encode_limit`]'s inverse); anything else is refused, naming it.
fn decode_limit(what: &str, value: f64) -> Result<Option<f64>, WireError> {
    match value {
        0.0 => Ok(None),
        value if value.is_finite() && value > 0.0 => Ok(Some(value)),
        value => Err(WireError::Malformed {
            message: "control",
            reason: format!("{what} {value} is neither 0 (none) nor a finite number > 0"),
        }),
    }
}
const CONTROL_SWAP: u32 = 2;
const CONTROL_SHUTDOWN: u32 = 3;

impl ControlMsg {
    /// Encodes a request. Fails on a model path longer than [`MODEL_PATH_LEN`] bytes or not UTF-8.
    pub fn encode(request: &ControlRequest) -> Result<ControlMsg, WireError> {
        let mut msg = ControlMsg {
            kind: 0,
            beams: 0,
            generation: 0,
            max_range: 0.0,
            max_wheel_speed: 0.0,
            max_wheel_accel: 0.0,
            request_id: 0,
            at_tick: 0,
            path: [0; MODEL_PATH_LEN],
        };
        match request {
            ControlRequest::BeginEpisode {
                generation,
                lidar,
                wheels,
            } => {
                msg.kind = CONTROL_BEGIN;
                msg.generation = *generation;
                msg.beams = u32::try_from(lidar.beams)
                    .map_err(|_| WireError::TooManyBeams { beams: lidar.beams })?;
                msg.max_range = lidar.max_range;
                msg.max_wheel_speed = encode_limit(WHEEL_SPEED_LIMIT, wheels.max_speed)?;
                msg.max_wheel_accel = encode_limit(WHEEL_ACCEL_LIMIT, wheels.max_accel)?;
            }
            ControlRequest::SwapModel {
                request_id,
                at_tick,
                path,
            } => {
                let text = path.to_str().ok_or_else(|| WireError::Malformed {
                    message: "control",
                    reason: format!("model path {} is not UTF-8", path.display()),
                })?;
                msg.kind = CONTROL_SWAP;
                msg.request_id = *request_id;
                msg.at_tick = *at_tick;
                msg.path = encode_text("model path", text)?;
            }
            ControlRequest::Shutdown => msg.kind = CONTROL_SHUTDOWN,
        }
        Ok(msg)
    }

    /// Decodes the request.
    pub fn decode(&self) -> Result<ControlRequest, WireError> {
        match self.kind {
            CONTROL_BEGIN => Ok(ControlRequest::BeginEpisode {
                generation: self.generation,
                lidar: LidarSpec {
                    beams: self.beams as usize,
                    max_range: self.max_range,
                },
                wheels: WheelLimits {
                    max_speed: decode_limit(WHEEL_SPEED_LIMIT, self.max_wheel_speed)?,
                    max_accel: decode_limit(WHEEL_ACCEL_LIMIT, self.max_wheel_accel)?,
                },
            }),
            CONTROL_SWAP => Ok(ControlRequest::SwapModel {
                request_id: self.request_id,
                at_tick: self.at_tick,
                path: PathBuf::from(decode_text("control", &self.path)?),
            }),
            CONTROL_SHUTDOWN => Ok(ControlRequest::Shutdown),
            kind => Err(WireError::UnknownKind {
                message: "control",
                kind,
            }),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Status: agent -> world
// ---------------------------------------------------------------------------------------------

/// What an agent tells the world, outside the per-tick exchange.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum AgentStatus {
    /// The agent is up (its ports exist) with this model; sent once at start.
    Hello {
        /// The agent's process id.
        pid: u32,
        /// The model it loaded.
        model_id: String,
    },
    /// Ready for the episode of this generation.
    Ready {
        /// The episode's generation.
        generation: u64,
        /// The model that will drive.
        model_id: String,
    },
    /// Cannot take part in the episode of this generation (e.g. the model does not fit the sensor).
    Refused {
        /// The episode's generation.
        generation: u64,
        /// Why, phrased for the user.
        reason: String,
    },
    /// The model of swap request `request_id` drives from tick `tick` on.
    SwapDone {
        /// The request.
        request_id: u64,
        /// First tick decided by the new model.
        tick: u64,
        /// The new model's id.
        model_id: String,
    },
    /// Swap request `request_id` was refused; the old model keeps driving.
    SwapRefused {
        /// The request.
        request_id: u64,
        /// Why, phrased for the user.
        reason: String,
    },
}

/// The wire form of an [`AgentStatus`].
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[cfg_attr(
    feature = "iceoryx2",
    derive(ZeroCopySend),
    type_name("formation.StatusMsg.v2")
)]
#[repr(C)]
pub struct StatusMsg {
    /// 1 hello, 2 ready, 3 refused, 4 swap done, 5 swap refused.
    pub kind: u32,
    /// Process id (hello).
    pub pid: u32,
    /// Episode generation (ready, refused).
    pub generation: u64,
    /// Swap request id (swap done, swap refused).
    pub request_id: u64,
    /// First tick of the new model (swap done).
    pub tick: u64,
    /// Model id, UTF-8, zero padded (hello, ready, swap done).
    pub model_id: [u8; MODEL_ID_LEN],
    /// Reason, UTF-8, zero padded, possibly truncated (refused, swap refused).
    pub reason: [u8; REASON_LEN],
}

const STATUS_HELLO: u32 = 1;
const STATUS_READY: u32 = 2;
const STATUS_REFUSED: u32 = 3;
const STATUS_SWAP_DONE: u32 = 4;
const STATUS_SWAP_REFUSED: u32 = 5;

impl StatusMsg {
    /// Encodes a status. Fails on a model id longer than [`MODEL_ID_LEN`] bytes; reasons longer
    /// than [`REASON_LEN`] bytes are truncated.
    pub fn encode(status: &AgentStatus) -> Result<StatusMsg, WireError> {
        let mut msg = StatusMsg {
            kind: 0,
            pid: 0,
            generation: 0,
            request_id: 0,
            tick: 0,
            model_id: [0; MODEL_ID_LEN],
            reason: [0; REASON_LEN],
        };
        match status {
            AgentStatus::Hello { pid, model_id } => {
                msg.kind = STATUS_HELLO;
                msg.pid = *pid;
                msg.model_id = encode_text("model id", model_id)?;
            }
            AgentStatus::Ready {
                generation,
                model_id,
            } => {
                msg.kind = STATUS_READY;
                msg.generation = *generation;
                msg.model_id = encode_text("model id", model_id)?;
            }
            AgentStatus::Refused { generation, reason } => {
                msg.kind = STATUS_REFUSED;
                msg.generation = *generation;
                msg.reason = encode_text_lossy(reason);
            }
            AgentStatus::SwapDone {
                request_id,
                tick,
                model_id,
            } => {
                msg.kind = STATUS_SWAP_DONE;
                msg.request_id = *request_id;
                msg.tick = *tick;
                msg.model_id = encode_text("model id", model_id)?;
            }
            AgentStatus::SwapRefused { request_id, reason } => {
                msg.kind = STATUS_SWAP_REFUSED;
                msg.request_id = *request_id;
                msg.reason = encode_text_lossy(reason);
            }
        }
        Ok(msg)
    }

    /// Decodes the status.
    pub fn decode(&self) -> Result<AgentStatus, WireError> {
        let model_id = || decode_text("status", &self.model_id).map(str::to_owned);
        let reason = || decode_text("status", &self.reason).map(str::to_owned);
        Ok(match self.kind {
            STATUS_HELLO => AgentStatus::Hello {
                pid: self.pid,
                model_id: model_id()?,
            },
            STATUS_READY => AgentStatus::Ready {
                generation: self.generation,
                model_id: model_id()?,
            },
            STATUS_REFUSED => AgentStatus::Refused {
                generation: self.generation,
                reason: reason()?,
            },
            STATUS_SWAP_DONE => AgentStatus::SwapDone {
                request_id: self.request_id,
                tick: self.tick,
                model_id: model_id()?,
            },
            STATUS_SWAP_REFUSED => AgentStatus::SwapRefused {
                request_id: self.request_id,
                reason: reason()?,
            },
            kind => {
                return Err(WireError::UnknownKind {
                    message: "status",
                    kind,
                });
            }
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Swap: `formation swap` -> world -> agent, and the world's reply
// ---------------------------------------------------------------------------------------------

/// A user's request, sent by `formation swap` to the world of a run, to change the model of one
/// robot's agent. The world forwards it to that agent as a [`ControlRequest::SwapModel`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SwapRequest {
    /// Id chosen by the requester; the reply carries it back.
    pub request_id: u64,
    /// The robot whose agent should swap.
    pub robot: usize,
    /// First tick the new model may drive (0: as soon as it is loaded).
    pub at_tick: u64,
    /// The ONNX model file (absolute, so that the agent resolves it as the user meant).
    pub path: PathBuf,
}

/// The wire form of a [`SwapRequest`].
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[cfg_attr(
    feature = "iceoryx2",
    derive(ZeroCopySend),
    type_name("formation.SwapRequestMsg.v1")
)]
#[repr(C)]
pub struct SwapRequestMsg {
    /// Request id.
    pub request_id: u64,
    /// Robot index.
    pub robot: u64,
    /// First tick the new model may drive.
    pub at_tick: u64,
    /// Model path, UTF-8, zero padded.
    pub path: [u8; MODEL_PATH_LEN],
}

impl SwapRequestMsg {
    /// Encodes a request. Fails on a model path that is not UTF-8 or longer than
    /// [`MODEL_PATH_LEN`] bytes.
    pub fn encode(request: &SwapRequest) -> Result<SwapRequestMsg, WireError> {
        let text = request.path.to_str().ok_or_else(|| WireError::Malformed {
            message: "swap request",
            reason: format!("model path {} is not UTF-8", request.path.display()),
        })?;
        Ok(SwapRequestMsg {
            request_id: request.request_id,
            robot: request.robot as u64,
            at_tick: request.at_tick,
            path: encode_text("model path", text)?,
        })
    }

    /// Decodes the request.
    pub fn decode(&self) -> Result<SwapRequest, WireError> {
        Ok(SwapRequest {
            request_id: self.request_id,
            robot: usize::try_from(self.robot).unwrap_or(usize::MAX),
            at_tick: self.at_tick,
            path: PathBuf::from(decode_text("swap request", &self.path)?),
        })
    }
}

/// How a [`SwapRequest`] ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SwapOutcome {
    /// The new model drives robot `robot` from tick `tick` on.
    Done {
        /// First tick decided by the new model.
        tick: u64,
        /// The new model's id.
        model_id: String,
    },
    /// Refused by the world (unknown robot, no agent) or by the agent (the model failed to load
    /// or validate); the old model keeps driving.
    Refused {
        /// Why, phrased for the user.
        reason: String,
    },
}

/// The world's answer to a [`SwapRequest`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SwapReply {
    /// The request this answers.
    pub request_id: u64,
    /// The robot of the request.
    pub robot: usize,
    /// What happened.
    pub outcome: SwapOutcome,
}

/// The wire form of a [`SwapReply`].
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[cfg_attr(
    feature = "iceoryx2",
    derive(ZeroCopySend),
    type_name("formation.SwapReplyMsg.v2")
)]
#[repr(C)]
pub struct SwapReplyMsg {
    /// Request id.
    pub request_id: u64,
    /// Robot index.
    pub robot: u64,
    /// 1 done, 2 refused.
    pub kind: u32,
    /// Keeps the layout explicit; always 0.
    pub reserved: u32,
    /// First tick of the new model (done).
    pub tick: u64,
    /// Model id, UTF-8, zero padded (done).
    pub model_id: [u8; MODEL_ID_LEN],
    /// Reason, UTF-8, zero padded, possibly truncated (refused).
    pub reason: [u8; REASON_LEN],
}

const SWAP_DONE: u32 = 1;
const SWAP_REFUSED: u32 = 2;

impl SwapReplyMsg {
    /// Encodes a reply. Fails on a model id longer than [`MODEL_ID_LEN`] bytes; reasons longer
    /// than [`REASON_LEN`] bytes are truncated.
    pub fn encode(reply: &SwapReply) -> Result<SwapReplyMsg, WireError> {
        let mut msg = SwapReplyMsg {
            request_id: reply.request_id,
            robot: reply.robot as u64,
            kind: 0,
            reserved: 0,
            tick: 0,
            model_id: [0; MODEL_ID_LEN],
            reason: [0; REASON_LEN],
        };
        match &reply.outcome {
            SwapOutcome::Done { tick, model_id } => {
                msg.kind = SWAP_DONE;
                msg.tick = *tick;
                msg.model_id = encode_text("model id", model_id)?;
            }
            SwapOutcome::Refused { reason } => {
                msg.kind = SWAP_REFUSED;
                msg.reason = encode_text_lossy(reason);
            }
        }
        Ok(msg)
    }

    /// Decodes the reply.
    pub fn decode(&self) -> Result<SwapReply, WireError> {
        let outcome = match self.kind {
            SWAP_DONE => SwapOutcome::Done {
                tick: self.tick,
                model_id: decode_text("swap reply", &self.model_id)?.to_owned(),
            },
            SWAP_REFUSED => SwapOutcome::Refused {
                reason: decode_text("swap reply", &self.reason)?.to_owned(),
            },
            kind => {
                return Err(WireError::UnknownKind {
                    message: "swap reply",
                    kind,
                });
            }
        };
        Ok(SwapReply {
            request_id: self.request_id,
            robot: usize::try_from(self.robot).unwrap_or(usize::MAX),
            outcome,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Progress events: world stdout -> launcher
// ---------------------------------------------------------------------------------------------

/// A progress event the world prints on its stdout, one JSON object per line
/// (`{"event":"run_done","index":3,"log":"..."}`), for the launcher to follow.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum WorldEvent {
    /// The world's services exist; agents may connect.
    Listening {
        /// Robots served.
        robots: usize,
    },
    /// Before the first run: robot `robot`'s agent said hello, `connected` of `robots` so far.
    AgentConnected {
        /// The robot.
        robot: usize,
        /// Agents connected so far.
        connected: usize,
        /// Robots in the team.
        robots: usize,
    },
    /// Every agent said hello.
    AgentsConnected,
    /// A run finished and its logs are written.
    RunDone {
        /// Run index.
        index: usize,
        /// The trajectory log.
        log: PathBuf,
    },
    /// Robot `robot`'s agent died; its robot brakes until an agent rejoins.
    AgentLost {
        /// The robot.
        robot: usize,
        /// The last tick the world published when it noticed.
        tick: u64,
        /// The last tick whose command from the dead agent the world applied, if any.
        last_fresh_tick: Option<u64>,
    },
    /// A process asked to drive robot `robot` and was refused; the robot keeps its agent, or keeps
    /// braking if it has none.
    AgentRefused {
        /// The robot.
        robot: usize,
        /// The process id it gave.
        pid: u32,
        /// Why, phrased for the user.
        reason: String,
    },
    /// A restarted agent (process `pid`) drives robot `robot` again from tick `tick` on.
    AgentRejoined {
        /// The robot.
        robot: usize,
        /// The new agent's process id.
        pid: u32,
        /// The first tick it drove.
        tick: u64,
    },
    /// Robot `robot`'s link is degraded: more than [`DEGRADED_SHARE_PERCENT`] % of its ticks in
    /// the last `window_ticks` ticks (`window_ms` of the run's time) were braked. Sent while the
    /// run goes on, at most once a second per robot.
    LinkDegraded {
        /// The robot.
        robot: usize,
        /// The tick at which the window ends.
        tick: u64,
        /// The window's length in the run's time \[ms\].
        window_ms: u64,
        /// The window's length in ticks.
        window_ticks: u64,
        /// Ticks of the window that were braked.
        braked: u64,
        /// Those braked ticks by reason ([`TickOutcome::name`]).
        reasons: std::collections::BTreeMap<String, u64>,
        /// The round trip of the newest command used in the window \[µs\], if one was used.
        round_trip_us: Option<u64>,
    },
    /// All runs finished.
    Finished,
    /// The world stops before its runs are done (an error such as a full disk, a signal, its
    /// input closed), said before it asks the agents to exit: the launcher then takes their
    /// exits for what they are and restarts none of them.
    Stopping {
        /// Why, phrased for the user (the world prints its error on stderr too).
        reason: String,
    },
}

/// The share of a robot's ticks, in percent, that may be braked within the degraded-link window
/// before [`WorldEvent::LinkDegraded`] is sent.
pub const DEGRADED_SHARE_PERCENT: u64 = 5;

impl WorldEvent {
    /// The event on one line of the world's stdout; `None` for any other line.
    pub fn parse(line: &str) -> Option<WorldEvent> {
        serde_json::from_str(line).ok()
    }

    /// The event as one line of JSON (without the newline).
    pub fn to_line(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

// ---------------------------------------------------------------------------------------------
// Timing log: written by the world per run, read by `formation profile` and the report
// ---------------------------------------------------------------------------------------------

/// What the world's watchdog made of one robot's command at one tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TickOutcome {
    /// The agent's command for this tick arrived in time and was applied.
    Fresh,
    /// No command of this episode arrived: braked.
    Missing,
    /// Only an older command arrived (lockstep), or the newest is too old (realtime): braked.
    Stale,
    /// The command was not a finite number: braked.
    NonFinite,
    /// The agent flagged a failed decision: braked.
    AgentFailed,
    /// No agent was ready to drive the robot: its agent died (or was lost) and no successor was
    /// ready yet, so nothing could answer: braked. Distinct from [`TickOutcome::Stale`] (an agent
    /// answered too late) and [`TickOutcome::AgentFailed`] (an agent answered that it could not
    /// decide). Timing logs written before it existed never hold it.
    AgentDown,
}

impl TickOutcome {
    /// Every outcome, in declaration order.
    pub const ALL: [TickOutcome; 6] = [
        TickOutcome::Fresh,
        TickOutcome::Missing,
        TickOutcome::Stale,
        TickOutcome::NonFinite,
        TickOutcome::AgentFailed,
        TickOutcome::AgentDown,
    ];

    /// The outcome's name in the files (`fresh`, `missing`, `stale`, `non_finite`,
    /// `agent_failed`, `agent_down`), as serde writes it.
    pub fn name(self) -> &'static str {
        match self {
            TickOutcome::Fresh => "fresh",
            TickOutcome::Missing => "missing",
            TickOutcome::Stale => "stale",
            TickOutcome::NonFinite => "non_finite",
            TickOutcome::AgentFailed => "agent_failed",
            TickOutcome::AgentDown => "agent_down",
        }
    }

    /// Whether the watchdog braked the robot (everything but [`TickOutcome::Fresh`]).
    pub fn braked(self) -> bool {
        self != TickOutcome::Fresh
    }
}

/// One robot's per-tick record of a run, stored column-wise (one entry per tick in every column)
/// so a 1200-tick run stays small. Durations are nanoseconds; 0 where no command was used.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RobotTiming {
    /// Distinct model ids in order of first use.
    pub model_ids: Vec<String>,
    /// Per tick: index into `model_ids` of the model that decided, or -1 when no command was used.
    pub model: Vec<i16>,
    /// Per tick: what the watchdog made of the command.
    pub outcome: Vec<TickOutcome>,
    /// Per tick: the scan the used command answered published → that command received by the
    /// world (the world's own clock). Under lag (`lag_ticks` > 0) this is the older scan's
    /// publication, not the current tick's.
    pub round_trip_ns: Vec<u64>,
    /// Per tick: the scan the used command answered published by the world → taken by the agent
    /// (system clock of both).
    pub uplink_ns: Vec<u64>,
    /// Per tick: occupancy rendering in the agent.
    pub occupancy_ns: Vec<u64>,
    /// Per tick: policy inference in the agent.
    pub inference_ns: Vec<u64>,
    /// Per tick: command published by the agent → taken by the world (system clock of both).
    pub downlink_ns: Vec<u64>,
    /// Per tick: how many ticks older than this one the scan was that the used command answered
    /// (0 in lockstep; realtime uses a command while its scan is within the stale window).
    #[serde(default)]
    pub lag_ticks: Vec<u32>,
}

impl RobotTiming {
    /// Appends one tick: the outcome, the command used (if any), its round trip (from the
    /// publication of the scan that command answered, tick `used.tick`, to its arrival), when the
    /// world published that same scan and when it took the command (both [`wall_clock_ns`]).
    pub fn record(
        &mut self,
        outcome: TickOutcome,
        used: Option<&CmdMsg>,
        round_trip: Option<std::time::Duration>,
        scan_published_wall_ns: u64,
        cmd_taken_wall_ns: u64,
    ) {
        self.outcome.push(outcome);
        let tick = self.outcome.len() as u64 - 1;
        self.lag_ticks.push(used.map_or(0, |msg| {
            u32::try_from(tick.saturating_sub(msg.tick)).unwrap_or(u32::MAX)
        }));
        let Some(msg) = used else {
            self.model.push(-1);
            self.round_trip_ns.push(0);
            self.uplink_ns.push(0);
            self.occupancy_ns.push(0);
            self.inference_ns.push(0);
            self.downlink_ns.push(0);
            return;
        };
        let id = msg.model_id().unwrap_or("<malformed>");
        let index = match self.model_ids.iter().position(|m| m == id) {
            Some(i) => i,
            None => {
                self.model_ids.push(id.to_owned());
                self.model_ids.len() - 1
            }
        };
        self.model.push(i16::try_from(index).unwrap_or(i16::MAX));
        let ns = |d: std::time::Duration| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        self.round_trip_ns.push(round_trip.map_or(0, ns));
        self.uplink_ns
            .push(msg.received_wall_ns.saturating_sub(scan_published_wall_ns));
        self.occupancy_ns.push(msg.occupancy_ns);
        self.inference_ns.push(msg.inference_ns);
        self.downlink_ns
            .push(cmd_taken_wall_ns.saturating_sub(msg.published_wall_ns));
    }

    /// Ticks recorded.
    pub fn ticks(&self) -> usize {
        self.outcome.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_ids_are_validated_and_generated_ids_are_valid() {
        assert!(RunId::new("abc-1_X").is_ok());
        for bad in ["", "a/b", "has space", "ü", &"x".repeat(MAX_RUN_ID_LEN + 1)] {
            assert!(
                matches!(RunId::new(bad), Err(WireError::InvalidRunId { .. })),
                "{bad:?}"
            );
        }
        let generated = RunId::generate();
        assert_eq!(RunId::new(generated.as_str()).as_ref(), Ok(&generated));
    }

    #[test]
    fn service_names_are_namespaced_by_run_robot_incarnation_and_channel() {
        let run = RunId::new("t1").unwrap();
        assert_eq!(
            robot_service_name(&run, 2, 0xab, RobotChannel::Scan),
            "formation/t1/robot/2/00000000000000ab/scan"
        );
        assert_eq!(
            lobby_service_name(&run, 0, LobbyChannel::Hello),
            "formation/t1/robot/0/hello"
        );
        let names: std::collections::HashSet<_> = RobotChannel::ALL
            .iter()
            .flat_map(|&c| {
                [
                    robot_service_name(&run, 0, 1, c),
                    robot_service_name(&run, 0, 2, c),
                ]
            })
            .chain([
                lobby_service_name(&run, 0, LobbyChannel::Hello),
                lobby_service_name(&run, 0, LobbyChannel::Welcome),
            ])
            .collect();
        assert_eq!(names.len(), 10, "every incarnation has services of its own");
    }

    #[test]
    fn messages_round_trip_through_their_bytes_and_a_wrong_size_is_refused() {
        let goal = Goal {
            phi_star: 1.0,
            d_star: 2.0,
            v_star: 0.3,
        };
        let scan = ScanMsg::new(3, 17, 0.85, -0.5, &goal, &[1.5, f32::INFINITY, 0.25]).unwrap();
        let bytes = message_bytes(&scan).to_vec();
        assert_eq!(bytes.len(), std::mem::size_of::<ScanMsg>());
        let back: ScanMsg = message_from_bytes("scan", &bytes).unwrap();
        assert_eq!(message_bytes(&back), &bytes[..], "bit for bit");
        assert_eq!(back.ranges().unwrap(), &[1.5, f32::INFINITY, 0.25]);
        let short = message_from_bytes::<ScanMsg>("scan", &bytes[1..]);
        assert!(
            matches!(&short, Err(WireError::Malformed { message: "scan", reason })
                if reason.contains("different builds")),
            "{short:?}"
        );
        let welcome = WelcomeMsg::encode(9, &Welcome::Refused("taken".into()));
        let back: WelcomeMsg = message_from_bytes("welcome", message_bytes(&welcome)).unwrap();
        assert_eq!(back.decode().unwrap(), Welcome::Refused("taken".into()));
    }

    #[test]
    fn welcome_round_trips() {
        for welcome in [
            Welcome::Accepted,
            Welcome::Refused("robot 1 is taken".into()),
        ] {
            let msg = WelcomeMsg::encode(7, &welcome);
            assert_eq!(msg.nonce, 7);
            assert_eq!(msg.decode().unwrap(), welcome);
        }
    }

    #[test]
    fn long_reasons_are_cut_at_a_word_and_say_so() {
        let reason = "word ".repeat(REASON_LEN);
        let bytes: [u8; REASON_LEN] = encode_text_lossy(&reason);
        let text = decode_text("test", &bytes).unwrap();
        assert!(text.ends_with("word …"), "{text:?}");
        assert!(text.len() <= REASON_LEN);
        let short: [u8; REASON_LEN] = encode_text_lossy("fits");
        assert_eq!(decode_text("test", &short).unwrap(), "fits");
    }

    #[test]
    fn scan_keeps_ranges_and_goal_and_rejects_oversized_scans() {
        let goal = Goal {
            phi_star: 1.0,
            d_star: 2.0,
            v_star: 0.7,
        };
        let ranges: Vec<f32> = (0..360).map(|k| k as f32 * 0.01).collect();
        let msg = ScanMsg::new(3, 7, 0.35, -0.5, &goal, &ranges).unwrap();
        assert_eq!(msg.ranges().unwrap(), &ranges[..]);
        assert_eq!(msg.goal(), goal);
        assert!(msg.ranges[360..].iter().all(|&r| r == 0.0));
        let too_many = vec![1.0; MAX_BEAMS + 1];
        assert_eq!(
            ScanMsg::new(0, 0, 0.0, 0.0, &goal, &too_many).unwrap_err(),
            WireError::TooManyBeams {
                beams: MAX_BEAMS + 1
            }
        );
        let mut corrupt = msg;
        corrupt.n_beams = MAX_BEAMS as u32 + 5;
        assert!(matches!(corrupt.ranges(), Err(WireError::Malformed { .. })));
    }

    #[test]
    fn world_events_round_trip_as_json_lines() {
        let event = WorldEvent::RunDone {
            index: 3,
            log: PathBuf::from("/o/runs/run-0003.json"),
        };
        let line = event.to_line();
        assert_eq!(
            line,
            r#"{"event":"run_done","index":3,"log":"/o/runs/run-0003.json"}"#
        );
        assert_eq!(WorldEvent::parse(&line), Some(event));
        assert_eq!(
            WorldEvent::parse(r#"{"event":"agent_rejoined","robot":1,"pid":42,"tick":57}"#),
            Some(WorldEvent::AgentRejoined {
                robot: 1,
                pid: 42,
                tick: 57
            })
        );
        assert_eq!(WorldEvent::parse("not json"), None);
        assert_eq!(WorldEvent::parse(r#"{"event":"unknown"}"#), None);
    }

    #[test]
    fn swap_request_and_reply_round_trip() {
        let request = SwapRequest {
            request_id: 77,
            robot: 2,
            at_tick: 40,
            path: PathBuf::from("/models/new.onnx"),
        };
        assert_eq!(
            SwapRequestMsg::encode(&request).unwrap().decode().unwrap(),
            request
        );
        let long = SwapRequest {
            path: PathBuf::from("m".repeat(MODEL_PATH_LEN + 1)),
            ..request
        };
        assert!(matches!(
            SwapRequestMsg::encode(&long),
            Err(WireError::TextTooLong { .. })
        ));
        for outcome in [
            SwapOutcome::Done {
                tick: 41,
                model_id: "policy-1234".into(),
            },
            SwapOutcome::Refused {
                reason: "wrong input shape".into(),
            },
        ] {
            let reply = SwapReply {
                request_id: 77,
                robot: 2,
                outcome,
            };
            assert_eq!(
                SwapReplyMsg::encode(&reply).unwrap().decode().unwrap(),
                reply
            );
        }
        let mut unknown = SwapReplyMsg::encode(&SwapReply {
            request_id: 1,
            robot: 0,
            outcome: SwapOutcome::Refused { reason: "x".into() },
        })
        .unwrap();
        unknown.kind = 9;
        assert!(matches!(
            unknown.decode(),
            Err(WireError::UnknownKind { .. })
        ));
    }

    #[test]
    fn command_round_trips_and_refuses_a_long_model_id() {
        let timings = AgentTimings {
            received_wall_ns: 5,
            occupancy_ns: 6,
            inference_ns: 7,
        };
        let cmd = WheelCmd::new(0.25, -0.5);
        let status = CmdStatus::OK.with(CmdStatus::MODEL_SWAPPED);
        let msg = CmdMsg::new(1, 2, cmd, "policy-abc123", timings, status).unwrap();
        assert_eq!(msg.wheels(), cmd);
        assert_eq!(msg.model_id().unwrap(), "policy-abc123");
        assert_eq!(msg.timings(), timings);
        assert!(msg.status().contains(CmdStatus::MODEL_SWAPPED));
        assert!(!msg.status().contains(CmdStatus::DECISION_FAILED));
        let long = "m".repeat(MODEL_ID_LEN + 1);
        assert!(matches!(
            CmdMsg::new(1, 2, cmd, &long, timings, status),
            Err(WireError::TextTooLong {
                field: "model id",
                ..
            })
        ));
    }

    #[test]
    fn control_requests_round_trip() {
        let requests = [
            ControlRequest::BeginEpisode {
                generation: 9,
                lidar: LidarSpec {
                    beams: 360,
                    max_range: 3.5,
                },
                wheels: WheelLimits::default(),
            },
            ControlRequest::BeginEpisode {
                generation: 10,
                lidar: LidarSpec::default(),
                wheels: WheelLimits {
                    max_speed: Some(0.9),
                    max_accel: Some(1.0),
                },
            },
            ControlRequest::BeginEpisode {
                generation: 11,
                lidar: LidarSpec::default(),
                wheels: WheelLimits {
                    max_speed: Some(0.22),
                    max_accel: None,
                },
            },
            ControlRequest::SwapModel {
                request_id: 4,
                at_tick: 100,
                path: "/m/policy.onnx".into(),
            },
            ControlRequest::Shutdown,
        ];
        for request in requests {
            assert_eq!(
                ControlMsg::encode(&request).unwrap().decode().unwrap(),
                request
            );
        }
        // A limit that is no limit is refused both ways, naming it.
        for (wheels, named) in [
            (
                WheelLimits {
                    max_speed: None,
                    max_accel: Some(-1.0),
                },
                "wheel acceleration limit -1",
            ),
            (
                WheelLimits {
                    max_speed: Some(f64::INFINITY),
                    max_accel: None,
                },
                "wheel speed limit inf",
            ),
        ] {
            let bad_limit = ControlRequest::BeginEpisode {
                generation: 1,
                lidar: LidarSpec::default(),
                wheels,
            };
            let error = ControlMsg::encode(&bad_limit).unwrap_err().to_string();
            assert!(error.contains(named), "{error}");
        }
        let begin = ControlMsg::encode(&ControlRequest::BeginEpisode {
            generation: 1,
            lidar: LidarSpec::default(),
            wheels: WheelLimits::default(),
        })
        .unwrap();
        let mut nan = begin;
        nan.max_wheel_accel = f64::NAN;
        let error = nan.decode().unwrap_err().to_string();
        assert!(error.contains("wheel acceleration limit NaN"), "{error}");
        let mut negative = begin;
        negative.max_wheel_speed = -0.5;
        let error = negative.decode().unwrap_err().to_string();
        assert!(error.contains("wheel speed limit -0.5"), "{error}");
        let mut unknown = ControlMsg::encode(&ControlRequest::Shutdown).unwrap();
        unknown.kind = 77;
        assert_eq!(
            unknown.decode().unwrap_err(),
            WireError::UnknownKind {
                message: "control",
                kind: 77
            }
        );
    }

    #[test]
    fn statuses_round_trip_and_long_reasons_are_cut_at_a_char_boundary() {
        let statuses = [
            AgentStatus::Hello {
                pid: 42,
                model_id: "a".into(),
            },
            AgentStatus::Ready {
                generation: 3,
                model_id: "b".into(),
            },
            AgentStatus::Refused {
                generation: 3,
                reason: "beams differ".into(),
            },
            AgentStatus::SwapDone {
                request_id: 1,
                tick: 50,
                model_id: "c".into(),
            },
            AgentStatus::SwapRefused {
                request_id: 2,
                reason: "no such file".into(),
            },
        ];
        for status in statuses {
            assert_eq!(
                StatusMsg::encode(&status).unwrap().decode().unwrap(),
                status
            );
        }
        let long = "é".repeat(REASON_LEN);
        let msg = StatusMsg::encode(&AgentStatus::Refused {
            generation: 0,
            reason: long,
        })
        .unwrap();
        match msg.decode().unwrap() {
            AgentStatus::Refused { reason, .. } => {
                assert!(reason.len() <= REASON_LEN, "{}", reason.len());
                assert!(reason.ends_with(" …"), "a cut reason says so");
                assert!(reason.trim_end_matches(" …").chars().all(|c| c == 'é'));
            }
            other => panic!("decoded {other:?}"),
        }
    }

    #[test]
    fn outcome_names_are_the_names_in_the_files_and_old_names_still_read() {
        for outcome in TickOutcome::ALL {
            assert_eq!(
                serde_json::to_string(&outcome).unwrap(),
                format!("\"{}\"", outcome.name())
            );
            assert_eq!(outcome.braked(), outcome != TickOutcome::Fresh);
        }
        let old: Vec<TickOutcome> =
            serde_json::from_str(r#"["fresh","missing","stale","non_finite","agent_failed"]"#)
                .unwrap();
        assert_eq!(old, TickOutcome::ALL[..5]);
    }

    #[test]
    fn a_degraded_link_event_is_one_json_line() {
        let event = WorldEvent::LinkDegraded {
            robot: 1,
            tick: 205,
            window_ms: 5000,
            window_ticks: 100,
            braked: 7,
            reasons: std::collections::BTreeMap::from([("stale".to_owned(), 7)]),
            round_trip_us: Some(101_000),
        };
        let line = event.to_line();
        assert!(
            line.starts_with(r#"{"event":"link_degraded","robot":1,"#),
            "{line}"
        );
        assert_eq!(WorldEvent::parse(&line), Some(event));
    }

    #[test]
    fn timing_log_records_used_commands_and_gaps() {
        let timings = AgentTimings {
            received_wall_ns: 1_500,
            occupancy_ns: 20,
            inference_ns: 30,
        };
        let mut a = CmdMsg::new(1, 0, WheelCmd::BRAKE, "a", timings, CmdStatus::OK).unwrap();
        let mut b = CmdMsg::new(1, 2, WheelCmd::BRAKE, "b", timings, CmdStatus::OK).unwrap();
        a.published_wall_ns = 1_600;
        b.published_wall_ns = 1_650;
        let mut log = RobotTiming::default();
        let ns = std::time::Duration::from_nanos;
        log.record(TickOutcome::Fresh, Some(&a), Some(ns(900)), 1_000, 1_900);
        log.record(TickOutcome::Missing, None, None, 2_000, 0);
        log.record(TickOutcome::Fresh, Some(&b), Some(ns(800)), 1_200, 2_000);
        log.record(TickOutcome::Fresh, Some(&a), Some(ns(700)), 1_000, 1_700);
        assert_eq!(log.ticks(), 4);
        assert_eq!(log.model_ids, vec!["a".to_owned(), "b".to_owned()]);
        assert_eq!(log.model, vec![0, -1, 1, 0]);
        assert_eq!(log.round_trip_ns, vec![900, 0, 800, 700]);
        assert_eq!(log.uplink_ns, vec![500, 0, 300, 500]);
        assert_eq!(log.downlink_ns, vec![300, 0, 350, 100]);
    }
}
