//! `formation swap` over Zenoh ([`request_swap`]): connects to the world's router (as user
//! `operator` when credentials are given), sends the swap request with the model's bytes after
//! it ([`super::model`]), and waits for the world's answer.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use ::zenoh::Wait;
use ::zenoh::qos::CongestionControl;
use formation_proto::wire::{
    RunId, SwapChannel, SwapReply, SwapReplyMsg, SwapRequest, SwapRequestMsg, WireError,
    message_bytes, message_from_bytes, swap_service_name,
};

use super::model::{ModelPayloadError, append_model};
use super::{Endpoint, Login};

/// Why a swap request over Zenoh got no answer.
#[derive(Debug, thiserror::Error)]
pub enum SwapClientError {
    /// The operator's TLS certificate is not usable, or the world refused it (feature `tls`).
    #[cfg(feature = "tls")]
    #[error(transparent)]
    Tls(#[from] super::tls::TlsError),
    /// The world's endpoint could not be reached (or refused the login).
    #[error(
        "cannot reach the world at {endpoint}: {detail}; is the run listening there, and are the \
         credentials (--credentials operator.json) those of this run?"
    )]
    Unreachable {
        /// The endpoint.
        endpoint: String,
        /// Zenoh's error.
        detail: String,
    },
    /// Zenoh refused an operation.
    #[error("zenoh could not {action} ({detail})")]
    Zenoh {
        /// What was being done.
        action: String,
        /// Zenoh's error.
        detail: String,
    },
    /// The model cannot be sent.
    #[error(transparent)]
    Model(#[from] ModelPayloadError),
    /// The request could not be encoded.
    #[error(transparent)]
    Wire(#[from] WireError),
    /// No answer in time.
    #[error(
        "run {run:?} at {endpoint} did not answer the swap request within {waited_s:.1} s: check \
         --run, and that the operator's credentials are this run's (a request the access rules \
         deny is dropped without an answer)"
    )]
    NoAnswer {
        /// The run.
        run: String,
        /// The endpoint.
        endpoint: String,
        /// How long this process waited.
        waited_s: f64,
    },
}

/// Sends `request` with `model`'s bytes to run `run`'s world at `endpoint` and returns its answer.
pub fn request_swap(
    endpoint: &Endpoint,
    login: Option<&Login>,
    run: &RunId,
    request: &SwapRequest,
    model: &[u8],
    timeout: Duration,
) -> Result<SwapReply, SwapClientError> {
    let started = Instant::now();
    let mut payload = message_bytes(&SwapRequestMsg::encode(request)?).to_vec();
    append_model(&mut payload, model)?;
    #[cfg(feature = "tls")]
    super::check_tls_client(endpoint, login, timeout)?;
    let config = super::client_config(endpoint, timeout, login).map_err(|detail| {
        SwapClientError::Zenoh {
            action: format!("configure the connection to {endpoint}"),
            detail,
        }
    })?;
    let session = super::open(config).map_err(|detail| SwapClientError::Unreachable {
        endpoint: endpoint.to_string(),
        detail,
    })?;
    let (tx, replies) = mpsc::channel();
    let wanted = request.request_id;
    let reply_key = swap_service_name(run, SwapChannel::Reply);
    let _subscriber = session
        .declare_subscriber(reply_key.clone())
        .callback(move |sample| {
            let decoded =
                message_from_bytes::<SwapReplyMsg>("swap reply", &sample.payload().to_bytes())
                    .and_then(|msg| msg.decode());
            if let Ok(reply) = decoded
                && reply.request_id == wanted
            {
                let _ = tx.send(reply);
            }
        })
        .wait()
        .map_err(|e| SwapClientError::Zenoh {
            action: format!("subscribe to {reply_key}"),
            detail: e.to_string(),
        })?;
    session
        .put(swap_service_name(run, SwapChannel::Request), payload)
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| SwapClientError::Zenoh {
            action: "send the swap request".into(),
            detail: e.to_string(),
        })?;
    let left = timeout.saturating_sub(started.elapsed());
    replies
        .recv_timeout(left)
        .map_err(|_| SwapClientError::NoAnswer {
            run: run.to_string(),
            endpoint: endpoint.to_string(),
            waited_s: started.elapsed().as_secs_f64(),
        })
}
