//! The wire messages (formation-proto): what a Zenoh subscriber of the world, an agent or
//! `formation swap` receives from the network.
//!
//! Case: one byte naming the message, then the payload, exactly as
//! [`formation_proto::wire::message_from_bytes`] takes it off the network; decoded means the
//! payload had the right size and the message's own decoder (`decode`, `ranges`, `model_id`)
//! accepted it.

use std::path::PathBuf;

use formation_proto::wire::{
    AgentStatus, AgentTimings, CmdMsg, CmdStatus, ControlMsg, ControlRequest, HelloMsg, PROOF_LEN,
    ScanMsg, StatusMsg, SwapOutcome, SwapReply, SwapReplyMsg, SwapRequest, SwapRequestMsg, Welcome,
    WelcomeMsg, WireError, message_bytes, message_from_bytes,
};
use formation_proto::{Goal, LidarSpec, WheelCmd};

use super::{Refusal, Scratch, Seed, Target, seed_error};
use crate::FuzzError;
use crate::mutate::Shape;

/// The target.
pub const TARGET: Target = Target {
    name: "wire",
    about: "the world/agent/swap wire messages: message_from_bytes + each message's decode",
    run,
    seeds,
    tokens: &[
        &[0; 8],
        &[0xff; 4],
        b"policy.onnx",
        &[0xc3, 0x28],
        &[0xe2, 0x80, 0xa6],
    ],
    shape: Shape::FixedLength,
};

const HELLO: u8 = 0;
const WELCOME: u8 = 1;
const SCAN: u8 = 2;
const CMD: u8 = 3;
const CONTROL: u8 = 4;
const STATUS: u8 = 5;
const SWAP_REQUEST: u8 = 6;
const SWAP_REPLY: u8 = 7;

fn decoded<T>(result: Result<T, WireError>) -> Result<(), Refusal> {
    result.map(|_| ()).map_err(Refusal::of)
}

fn run(_: &Scratch, case: &[u8]) -> Result<(), Refusal> {
    let Some((&kind, payload)) = case.split_first() else {
        return Err(Refusal::named("empty"));
    };
    match kind % 8 {
        HELLO => decoded(message_from_bytes::<HelloMsg>("hello", payload)),
        WELCOME => decoded(message_from_bytes::<WelcomeMsg>("welcome", payload)?.decode()),
        SCAN => {
            let scan = message_from_bytes::<ScanMsg>("scan", payload).map_err(Refusal::of)?;
            let _ = scan.goal();
            decoded(scan.ranges())
        }
        CMD => {
            let cmd = message_from_bytes::<CmdMsg>("command", payload).map_err(Refusal::of)?;
            let _ = (cmd.wheels(), cmd.status(), cmd.timings());
            decoded(cmd.model_id())
        }
        CONTROL => decoded(message_from_bytes::<ControlMsg>("control", payload)?.decode()),
        STATUS => decoded(message_from_bytes::<StatusMsg>("status", payload)?.decode()),
        SWAP_REQUEST => {
            decoded(message_from_bytes::<SwapRequestMsg>("swap request", payload)?.decode())
        }
        _ => decoded(message_from_bytes::<SwapReplyMsg>("swap reply", payload)?.decode()),
    }
}

impl From<WireError> for Refusal {
    fn from(e: WireError) -> Refusal {
        Refusal::of(e)
    }
}

/// The seed file `name`: a message's wire `bytes` behind the tag of its `kind`.
fn seed(name: &str, kind: u8, bytes: &[u8]) -> Seed {
    let mut case = vec![kind];
    case.extend_from_slice(bytes);
    (name.into(), case)
}

fn seeds() -> Result<Vec<Seed>, FuzzError> {
    let mut seeds = lobby_and_tick_seeds()?;
    seeds.extend(control_and_swap_seeds()?);
    Ok(seeds)
}

/// A hello, a refusal, a scan and a command.
fn lobby_and_tick_seeds() -> Result<Vec<Seed>, FuzzError> {
    let goal = Goal {
        phi_star: 0.3,
        d_star: 1.5,
        v_star: 0.3,
    };
    let ranges: Vec<f32> = (0..360).map(|k| 1.0 + (k as f32) * 0.01).collect();
    let hello = HelloMsg {
        pid: 4242,
        reserved: 0,
        nonce: 0x1234_5678_9abc_def0,
        proof: [7; PROOF_LEN],
    };
    let welcome = WelcomeMsg::encode(7, &Welcome::Refused("robot 1 is taken".into()));
    let scan = ScanMsg::new(3, 17, 0.85, 0.25, &goal, &ranges).map_err(seed_error("wire"))?;
    let cmd = CmdMsg::new(
        3,
        17,
        WheelCmd {
            left: 0.31,
            right: 0.29,
        },
        "policy-3f2a",
        AgentTimings {
            received_wall_ns: 1,
            occupancy_ns: 30_000,
            inference_ns: 130_000,
        },
        CmdStatus::MODEL_SWAPPED,
    )
    .map_err(seed_error("wire"))?;
    Ok(vec![
        seed("hello.bin", HELLO, message_bytes(&hello)),
        seed("welcome-refused.bin", WELCOME, message_bytes(&welcome)),
        seed("scan.bin", SCAN, message_bytes(&scan)),
        seed("cmd.bin", CMD, message_bytes(&cmd)),
    ])
}

/// Control requests, statuses, a swap request and its reply.
fn control_and_swap_seeds() -> Result<Vec<Seed>, FuzzError> {
    let begin = ControlMsg::encode(&ControlRequest::BeginEpisode {
        generation: 3,
        lidar: LidarSpec {
            beams: 360,
            max_range: 4.0,
        },
        // No top speed: the seed's bytes stay those of the message before it had one.
        wheels: formation_proto::WheelLimits {
            max_speed: None,
            max_accel: Some(1.0),
        },
    })
    .map_err(seed_error("wire"))?;
    let swap_control = ControlMsg::encode(&ControlRequest::SwapModel {
        request_id: 9,
        at_tick: 100,
        path: PathBuf::from("/models/policy.onnx"),
    })
    .map_err(seed_error("wire"))?;
    let ready = StatusMsg::encode(&AgentStatus::Ready {
        generation: 3,
        model_id: "policy-3f2a".into(),
    })
    .map_err(seed_error("wire"))?;
    let refused = StatusMsg::encode(&AgentStatus::Refused {
        generation: 3,
        reason: "the model was trained for 360 beams, the robot has 90".into(),
    })
    .map_err(seed_error("wire"))?;
    let request = SwapRequestMsg::encode(&SwapRequest {
        request_id: 9,
        robot: 1,
        at_tick: 100,
        path: PathBuf::from("/models/policy.onnx"),
    })
    .map_err(seed_error("wire"))?;
    let reply = SwapReplyMsg::encode(&SwapReply {
        request_id: 9,
        robot: 1,
        outcome: SwapOutcome::Done {
            tick: 100,
            model_id: "policy-3f2a".into(),
        },
    })
    .map_err(seed_error("wire"))?;
    Ok(vec![
        seed("control-begin.bin", CONTROL, message_bytes(&begin)),
        seed("control-swap.bin", CONTROL, message_bytes(&swap_control)),
        seed("status-ready.bin", STATUS, message_bytes(&ready)),
        seed("status-refused.bin", STATUS, message_bytes(&refused)),
        seed("swap-request.bin", SWAP_REQUEST, message_bytes(&request)),
        seed("swap-reply.bin", SWAP_REPLY, message_bytes(&reply)),
    ])
}
