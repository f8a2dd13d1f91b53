//! `formation swap` over this transport ([`request_swap`]): a socket of the client's own in the
//! run's folder, one request to the world's socket, and the world's reply back there.

use std::time::{Duration, Instant};

use formation_proto::wire::{SwapReply, SwapReplyMsg, SwapRequest, SwapRequestMsg};
use formation_runtime::auth::fresh_nonce;
use formation_runtime::plugin::RunSite;

use crate::error::DatagramError;
use crate::folder::RunFolder;
use crate::frame::{Frame, Kind, MAX_DATAGRAM};
use crate::socket::{self, BoundSocket};

/// Sends `request` to the world of `site`'s run and waits up to `timeout` for its reply.
pub fn request_swap(
    site: &RunSite<'_>,
    request: &SwapRequest,
    timeout: Duration,
) -> Result<SwapReply, DatagramError> {
    let started = Instant::now();
    let folder = RunFolder::locate(site)?;
    let world = folder.world_socket();
    let nonce = fresh_nonce()?;
    let inbox = BoundSocket::bind(folder.swap_socket(nonce))?;
    let msg = SwapRequestMsg::encode(request)?;
    if !socket::send_once(
        &world,
        &Frame::encode(Kind::SwapRequest, request.robot, nonce, &msg),
    )? {
        return Err(DatagramError::WorldNotFound {
            run: folder.run().to_string(),
            dir: folder.dir().to_path_buf(),
            waited_s: started.elapsed().as_secs_f64(),
        });
    }
    let mut buffer = vec![0; MAX_DATAGRAM];
    loop {
        let left = timeout.saturating_sub(started.elapsed());
        if left.is_zero() {
            return Err(DatagramError::NoSwapReply {
                request_id: request.request_id,
                waited_s: started.elapsed().as_secs_f64(),
            });
        }
        let Some(len) = inbox.receive(&mut buffer, Some(left))? else {
            continue;
        };
        let Ok(frame) = Frame::decode(&buffer[..len]) else {
            continue;
        };
        if frame.kind == Kind::SwapReply && frame.incarnation == nonce {
            let reply = frame.message::<SwapReplyMsg>("swap reply")?.decode()?;
            if reply.request_id == request.request_id {
                return Ok(reply);
            }
        }
    }
}
