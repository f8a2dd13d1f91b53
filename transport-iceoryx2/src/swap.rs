//! `formation swap` over iceoryx2 ([`request_swap`]): publishes a swap request on the run's
//! swap channel and waits for the world's reply with the same request id. It opens the services
//! the world created (never creates one: a run that does not exist is
//! [`SwapClientError::UnknownRun`]), with the same definitions as the world
//! (`iceoryx::services`), and everything it opened goes when it returns.

use std::time::{Duration, Instant};

use formation_proto::wire::{
    SwapChannel, SwapReply, SwapReplyMsg, SwapRequest, SwapRequestMsg, WireError, swap_service_name,
};
use iceoryx2::prelude::*;

use super::naming::{RunNamespace, SWAP_NODE_NAME, swap_limits};
use super::services::{
    Access, ServiceError, ServiceErrorKind, event_service, pubsub_service, subscriber,
};
use crate::error::{IceoryxError, iox};

/// Why a swap request over iceoryx2 got no answer.
#[derive(Debug, thiserror::Error)]
pub enum SwapClientError {
    /// No world with this run id is running.
    #[error(
        "no run {run:?} is running (its swap service does not exist): `formation run` prints the \
         run id it uses, or set one with `formation run --run-id ID`"
    )]
    UnknownRun {
        /// The run id asked for.
        run: String,
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
    #[error(transparent)]
    Iceoryx(#[from] IceoryxError),
    /// The request could not be encoded.
    #[error(transparent)]
    Wire(#[from] WireError),
}

/// The run's swap channel as this client opens it: a service that does not exist means no world
/// of this run is running.
fn open_failed(run: &str) -> impl Fn(ServiceError) -> SwapClientError + '_ {
    move |e| match e.kind {
        ServiceErrorKind::Name => e.open_failed().into(),
        ServiceErrorKind::Unavailable => SwapClientError::UnknownRun {
            run: run.to_owned(),
        },
    }
}

/// Sends `request` to the world of the run in `namespace` and waits up to `timeout` for its
/// reply.
pub fn request_swap(
    namespace: &RunNamespace,
    request: &SwapRequest,
    timeout: Duration,
) -> Result<SwapReply, SwapClientError> {
    let run = namespace.run().to_string();
    if !namespace.root_dir().exists() {
        return Err(SwapClientError::UnknownRun { run });
    }
    let msg = SwapRequestMsg::encode(request)?;
    let config = namespace
        .iceoryx_config()
        .map_err(iox("configure the run's namespace"))?;
    let node_name = NodeName::new(SWAP_NODE_NAME).map_err(iox("name the swap node"))?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .config(&config)
        .create::<ipc::Service>()
        .map_err(iox("create the swap node"))?;
    let name = |channel| swap_service_name(namespace.run(), channel);
    let open_failed = open_failed(&run);
    let (request_name, reply_name) = (name(SwapChannel::Request), name(SwapChannel::Reply));
    let (request_limits, reply_limits) = (
        swap_limits(SwapChannel::Request),
        swap_limits(SwapChannel::Reply),
    );
    let pubsub = |name: &str, limits| {
        pubsub_service::<SwapReplyMsg>(&node, name, limits, Access::Open).map_err(&open_failed)
    };
    let event =
        |name: &str, limits| event_service(&node, name, limits, Access::Open).map_err(&open_failed);
    // Subscribe to replies before asking, so the answer cannot be missed.
    let replies = subscriber(&pubsub(&reply_name, reply_limits)?, reply_limits)
        .map_err(iox("subscribe to swap replies (8 swaps at once at most)"))?;
    let reply_wake = event(&reply_name, reply_limits)?
        .listener_builder()
        .create()
        .map_err(iox("listen for swap replies"))?;
    let publisher =
        pubsub_service::<SwapRequestMsg>(&node, &request_name, request_limits, Access::Open)
            .map_err(&open_failed)?
            .publisher_builder()
            .create()
            .map_err(iox("publish a swap request (8 swaps at once at most)"))?;
    let request_wake = event(&request_name, request_limits)?
        .notifier_builder()
        .create()
        .map_err(iox("wake the world"))?;
    publisher
        .send_copy(msg)
        .map_err(iox("send the swap request"))?;
    request_wake.notify().map_err(iox("wake the world"))?;
    let started = Instant::now();
    loop {
        while let Some(sample) = replies.receive().map_err(iox("receive a swap reply"))? {
            if let Ok(reply) = sample.payload().decode()
                && reply.request_id == request.request_id
            {
                return Ok(reply);
            }
        }
        let left = timeout.saturating_sub(started.elapsed());
        if left.is_zero() {
            return Err(SwapClientError::NoAnswer {
                run: namespace.run().to_string(),
                waited_s: started.elapsed().as_secs_f64(),
            });
        }
        reply_wake
            .timed_wait(|_| {}, left.min(Duration::from_millis(100)))
            .map_err(iox("wait for the swap reply"))?;
    }
}
