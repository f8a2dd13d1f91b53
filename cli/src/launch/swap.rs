//! `formation swap`: asks the world of a running launch to change one robot's model.
//!
//! The request travels over the run's swap channel (see [`formation_proto::wire::SwapChannel`]):
//! this process publishes a [`SwapRequest`] to the world, the world forwards it to the robot's
//! agent as a control request without pausing its tick loop, the agent loads and validates the
//! model on a helper thread and swaps it in at a tick boundary, and the world relays the agent's
//! answer ([`SwapReply`]) back here. Everything this process creates in the run's iceoryx2
//! namespace is removed when it returns.
//!
//! With `--transport zenoh` ([`request_swap_over_zenoh`]) the request goes to the world's
//! Zenoh router instead, and carries the model's bytes (at most 32 MiB, with a SHA-256), since a
//! remote agent cannot open this host's path.
//!
//! The model file is checked here first by its metadata ([`formation_onnx::check_model_file`]): a
//! missing path, a directory, a FIFO, a device or a file over the size limit is refused before
//! any request is sent, and the agent refuses a candidate that does not fit the robot's sensor or
//! gives a non-finite command on its last observation.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context;
use formation_proto::wire::{
    RunId, SwapChannel, SwapOutcome, SwapReply, SwapReplyMsg, SwapRequest, SwapRequestMsg,
    swap_service_name,
};
use formation_runtime::iceoryx::naming::{RunNamespace, SWAP_NODE_NAME, swap_limits};
use iceoryx2::prelude::*;

/// Why a swap did not happen.
#[derive(Debug, thiserror::Error)]
pub enum SwapError {
    /// No world with this run id is running.
    #[error(
        "no run {run:?} is running (its swap service does not exist): `formation run` prints the \
         run id it uses, or set one with `formation run --run-id ID`"
    )]
    UnknownRun {
        /// The run id asked for.
        run: String,
    },
    /// The world or the agent refused; the old model keeps driving.
    #[error("swap refused for robot {robot}: {reason}")]
    Refused {
        /// The robot of the request.
        robot: usize,
        /// Why.
        reason: String,
    },
    /// No answer in time.
    #[error(
        "run {run:?} did not answer the swap request within {waited_s:.1} s; it may be stopping, or \
         the agent may still be loading (raise --timeout-s)"
    )]
    NoAnswer {
        /// The run id.
        run: String,
        /// How long this process waited.
        waited_s: f64,
    },
    /// iceoryx2 failed.
    #[error("iceoryx2 could not {action}: {detail}")]
    Iceoryx {
        /// What was being done.
        action: String,
        /// iceoryx2's error.
        detail: String,
    },
}

fn iox(action: &str) -> impl FnOnce(&dyn std::fmt::Debug) -> SwapError + '_ {
    move |e| SwapError::Iceoryx {
        action: action.to_owned(),
        detail: format!("{e:?}"),
    }
}

/// What a successful swap reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SwapDone {
    /// First tick the new model decided.
    pub tick: u64,
    /// The new model's id.
    pub model_id: String,
}

/// Asks run `run`'s world to make robot `robot` drive with `model` from tick `at_tick` on (0: as
/// soon as it is loaded), and waits up to `timeout` for the answer.
pub fn request_swap(
    run: &str,
    robot: usize,
    model: &Path,
    at_tick: u64,
    timeout: Duration,
) -> anyhow::Result<SwapDone> {
    let run_id = RunId::new(run)?;
    // Refused here by its metadata (missing, not a regular file, over the size limit) rather
    // than by the agent after it has read the file.
    formation_onnx::check_model_file(model)?;
    let path = std::fs::canonicalize(model)
        .with_context(|| format!("resolving model path {}", model.display()))?;
    let namespace = RunNamespace::new(&run_id);
    if !namespace.root_dir().exists() {
        return Err(SwapError::UnknownRun { run: run.into() }.into());
    }
    let request = SwapRequest {
        request_id: request_id(),
        robot,
        at_tick,
        path,
    };
    let reply = exchange(&namespace, &request, timeout)?;
    swap_done(reply.outcome, robot)
}

/// [`request_swap`] over Zenoh: sends the model's bytes to run `run`'s world at `connect`
/// (logging in with the login file `credentials`, the operator's), since a remote agent cannot
/// open this host's path.
#[cfg(feature = "zenoh")]
pub fn request_swap_over_zenoh(
    connect: &str,
    credentials: Option<&Path>,
    run: &str,
    robot: usize,
    model: &Path,
    at_tick: u64,
    timeout: Duration,
) -> anyhow::Result<SwapDone> {
    use formation_runtime::zenoh::{Endpoint, credentials as creds, model, swap};
    let run_id = RunId::new(run)?;
    let endpoint = Endpoint::parse(connect)?;
    let size = formation_onnx::check_model_file(model)?;
    if size > model::MAX_MODEL_BYTES as u64 {
        anyhow::bail!(
            "{}: {}",
            model.display(),
            model::ModelPayloadError::TooLarge { size }
        );
    }
    let bytes = formation_proto::files::read_bounded(model, model::MAX_MODEL_BYTES as u64)
        .map_err(|e| anyhow::anyhow!("reading model {}: {e:?}", model.display()))?;
    let login = credentials.map(creds::read_login).transpose()?;
    let name = model
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "model.onnx".into());
    let request = SwapRequest {
        request_id: request_id(),
        robot,
        at_tick,
        // Informative only: the agent stores the bytes and loads its own copy.
        path: std::path::PathBuf::from(format!("sent-over-zenoh/{name}")),
    };
    let reply = swap::request_swap(
        &endpoint,
        login.as_ref(),
        &run_id,
        &request,
        &bytes,
        timeout,
    )?;
    swap_done(reply.outcome, robot)
}

/// The world's answer about robot `robot` as the swap command's result.
fn swap_done(outcome: SwapOutcome, robot: usize) -> anyhow::Result<SwapDone> {
    match outcome {
        SwapOutcome::Done { tick, model_id } => Ok(SwapDone { tick, model_id }),
        SwapOutcome::Refused { reason } => Err(SwapError::Refused { robot, reason }.into()),
    }
}

/// A request id unlikely to collide with another `formation swap` at the same time.
fn request_id() -> u64 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0);
    (u64::from(std::process::id()) << 40) ^ nanos
}

fn exchange(
    namespace: &RunNamespace,
    request: &SwapRequest,
    timeout: Duration,
) -> Result<SwapReply, SwapError> {
    let run = namespace.run().to_string();
    let unknown = || SwapError::UnknownRun { run: run.clone() };
    let config = namespace
        .iceoryx_config()
        .map_err(|e| iox("configure the run's namespace")(&e))?;
    let node_name = NodeName::new(SWAP_NODE_NAME).map_err(|e| iox("name the swap node")(&e))?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .config(&config)
        .create::<ipc::Service>()
        .map_err(|e| iox("create the swap node")(&e))?;
    let service = |channel: SwapChannel| {
        ServiceName::new(&swap_service_name(namespace.run(), channel))
            .map_err(|e| iox("name the swap service")(&e))
    };
    let request_limits = swap_limits(SwapChannel::Request);
    let requests = node
        .service_builder(&service(SwapChannel::Request)?)
        .publish_subscribe::<SwapRequestMsg>()
        .max_publishers(request_limits.max_publishers)
        .max_subscribers(request_limits.max_subscribers)
        .subscriber_max_buffer_size(request_limits.subscriber_buffer)
        .open()
        .map_err(|_| unknown())?;
    let reply_limits = swap_limits(SwapChannel::Reply);
    let replies = node
        .service_builder(&service(SwapChannel::Reply)?)
        .publish_subscribe::<SwapReplyMsg>()
        .max_publishers(reply_limits.max_publishers)
        .max_subscribers(reply_limits.max_subscribers)
        .subscriber_max_buffer_size(reply_limits.subscriber_buffer)
        .open()
        .map_err(|_| unknown())?;
    let open_event = |channel: SwapChannel| {
        let limits = swap_limits(channel);
        node.service_builder(&service(channel)?)
            .event()
            .max_notifiers(limits.max_publishers)
            .max_listeners(limits.max_subscribers)
            .open()
            .map_err(|_| unknown())
    };
    // Subscribe to replies before asking, so the answer cannot be missed.
    let reply_sub = replies
        .subscriber_builder()
        .buffer_size(reply_limits.subscriber_buffer)
        .create()
        .map_err(|e| iox("subscribe to swap replies (8 swaps at once at most)")(&e))?;
    let reply_wake = open_event(SwapChannel::Reply)?
        .listener_builder()
        .create()
        .map_err(|e| iox("listen for swap replies")(&e))?;
    let publisher = requests
        .publisher_builder()
        .create()
        .map_err(|e| iox("publish a swap request (8 swaps at once at most)")(&e))?;
    let request_wake = open_event(SwapChannel::Request)?
        .notifier_builder()
        .create()
        .map_err(|e| iox("wake the world")(&e))?;
    let msg = SwapRequestMsg::encode(request).map_err(|e| SwapError::Refused {
        robot: request.robot,
        reason: e.to_string(),
    })?;
    publisher
        .send_copy(msg)
        .map_err(|e| iox("send the swap request")(&e))?;
    request_wake
        .notify()
        .map_err(|e| iox("wake the world")(&e))?;

    let started = Instant::now();
    loop {
        while let Some(sample) = reply_sub
            .receive()
            .map_err(|e| iox("receive a swap reply")(&e))?
        {
            if let Ok(reply) = sample.payload().decode()
                && reply.request_id == request.request_id
            {
                return Ok(reply);
            }
        }
        let left = timeout.saturating_sub(started.elapsed());
        if left.is_zero() {
            return Err(SwapError::NoAnswer {
                run,
                waited_s: started.elapsed().as_secs_f64(),
            });
        }
        reply_wake
            .timed_wait(|_| {}, left.min(Duration::from_millis(100)))
            .map_err(|e| iox("wait for the swap reply")(&e))?;
    }
}
