//! `formation swap`: asks the world of a running launch to change one robot's model.
//!
//! The request travels over the run's swap channel (see [`formation_proto::wire::SwapChannel`]):
//! this process publishes a [`SwapRequest`] to the world, the world forwards it to the robot's
//! agent as a control request without pausing its tick loop, the agent loads and validates the
//! model on a helper thread and swaps it in at a tick boundary, and the world relays the agent's
//! answer ([`formation_proto::wire::SwapReply`]) back here. The iceoryx2 client is the runtime's
//! ([`formation_transport_iceoryx2::request_swap`]), which opens the swap channel with the world's
//! own service definitions; everything it opens in the run's namespace goes when it returns.
//!
//! A registered transport carries it with its own client ([`request_swap_over_plugin`]).
//!
//! With `--transport zenoh` (`request_swap_over_zenoh`, feature `zenoh`) the request goes to the world's
//! Zenoh router instead, and carries the model's bytes (at most 32 MiB, with a SHA-256), since a
//! remote agent cannot open this host's path.
//!
//! The model file is checked here first by its metadata ([`formation_onnx::check_model_file`]): a
//! missing path, a directory, a FIFO, a device or a file over the size limit is refused before
//! any request is sent, and the agent refuses a candidate that does not fit the robot's sensor or
//! gives a non-finite command on its last observation.

use std::time::Duration;

use anyhow::Context;
use formation_proto::wire::{RunId, SwapOutcome, SwapRequest};
use formation_transport_iceoryx2::naming::RunNamespace;

use crate::args::SwapArgs;

/// The world or the agent refused a swap; the old model keeps driving.
#[derive(Debug, thiserror::Error)]
#[error("swap refused for robot {robot}: {reason}")]
pub struct SwapRefused {
    /// The robot of the request.
    pub robot: usize,
    /// Why.
    pub reason: String,
}

/// What a successful swap reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SwapDone {
    /// First tick the new model decided.
    pub tick: u64,
    /// The new model's id.
    pub model_id: String,
}

/// Asks the world of run `args.run` to make robot `args.robot` drive with `args.model` from tick
/// `args.at_tick` on (0: as soon as it is loaded), and waits up to `timeout` for the answer.
pub fn request_swap(args: &SwapArgs, timeout: Duration) -> anyhow::Result<SwapDone> {
    let (run_id, request) = request_on_this_host(args)?;
    let namespace = RunNamespace::new(&run_id);
    let reply = formation_transport_iceoryx2::request_swap(&namespace, &request, timeout)?;
    swap_done(reply.outcome, args.robot)
}

/// The run's id and the request of `args` to a world on this host, which opens the model at
/// its canonical path. The model is refused here by its metadata (missing, not a regular file,
/// over the size limit) rather than by the agent after it has read the file.
fn request_on_this_host(args: &SwapArgs) -> anyhow::Result<(RunId, SwapRequest)> {
    let run_id = RunId::new(&args.run)?;
    formation_onnx::check_model_file(&args.model)?;
    let path = std::fs::canonicalize(&args.model)
        .with_context(|| format!("resolving model path {}", args.model.display()))?;
    let request = SwapRequest {
        request_id: request_id(),
        robot: args.robot,
        at_tick: args.at_tick,
        path,
    };
    Ok((run_id, request))
}

/// [`request_swap`] over Zenoh: sends the model's bytes to the world of run `args.run` at
/// `connect` (logging in with the login file `args.reach.credentials`, the operator's), since a
/// remote agent cannot open this host's path.
#[cfg(feature = "zenoh")]
pub fn request_swap_over_zenoh(
    connect: &str,
    args: &SwapArgs,
    timeout: Duration,
) -> anyhow::Result<SwapDone> {
    use formation_transport_zenoh::{Endpoint, credentials as creds, model, swap};
    let run_id = RunId::new(&args.run)?;
    let endpoint = Endpoint::parse(connect)?;
    let size = formation_onnx::check_model_file(&args.model)?;
    if size > model::MAX_MODEL_BYTES as u64 {
        anyhow::bail!(
            "{}: {}",
            args.model.display(),
            model::ModelPayloadError::TooLarge { size }
        );
    }
    let bytes = formation_proto::files::read_bounded(&args.model, model::MAX_MODEL_BYTES as u64)
        .map_err(|e| anyhow::anyhow!("reading model {}: {e:?}", args.model.display()))?;
    let login = args
        .reach
        .credentials
        .as_deref()
        .map(creds::read_login)
        .transpose()?;
    let name = args
        .model
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "model.onnx".into());
    let request = SwapRequest {
        request_id: request_id(),
        robot: args.robot,
        at_tick: args.at_tick,
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
    swap_done(reply.outcome, args.robot)
}

/// [`request_swap`] over a registered transport, `endpoint` being its `--connect`.
pub fn request_swap_over_plugin(
    transport: &'static dyn formation_runtime::plugin::TransportPlugin,
    endpoint: Option<&str>,
    args: &SwapArgs,
    timeout: Duration,
) -> anyhow::Result<SwapDone> {
    let (run_id, request) = request_on_this_host(args)?;
    let site = formation_runtime::plugin::RunSite {
        run: &run_id,
        endpoint,
    };
    let reply = transport
        .request_swap(&site, &request, timeout)
        .map_err(
            |source| formation_runtime::transport::TransportError::Plugin {
                transport: transport.name(),
                action: "send the swap request",
                run: run_id.to_string(),
                source,
            },
        )?;
    swap_done(reply.outcome, args.robot)
}

/// The world's answer about robot `robot` as the swap command's result.
fn swap_done(outcome: SwapOutcome, robot: usize) -> anyhow::Result<SwapDone> {
    match outcome {
        SwapOutcome::Done { tick, model_id } => Ok(SwapDone { tick, model_id }),
        SwapOutcome::Refused { reason } => Err(SwapRefused { robot, reason }.into()),
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
