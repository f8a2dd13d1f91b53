//! One datagram of the transport ([`Frame`]): a 24-byte header (the magic `FUD1`, the [`Kind`],
//! the robot and the incarnation, which is the agent's nonce, or a swap client's) followed by
//! one wire message's own bytes (`formation_proto::wire::message_bytes`), in the host's byte
//! order: every process of a run is on this host.

use formation_proto::wire::{WireError, message_bytes, message_from_bytes};

/// The first bytes of every datagram of this transport (version 1).
const MAGIC: [u8; 4] = *b"FUD1";
/// Bytes of the header.
const HEADER_LEN: usize = 24;
/// The largest datagram a receiver takes (the largest wire message is a scan, under 4 KiB).
pub const MAX_DATAGRAM: usize = 16 * 1024;

/// What a datagram carries, and so which way it goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Agent → world: a `HelloMsg` (incarnation: its nonce).
    Hello = 1,
    /// World → agent: a `WelcomeMsg`.
    Welcome = 2,
    /// World → agent: a `ScanMsg`.
    Scan = 3,
    /// World → agent: a `ControlMsg`.
    Control = 4,
    /// Agent → world: a `CmdMsg`.
    Command = 5,
    /// Agent → world: a `StatusMsg`.
    Status = 6,
    /// Swap client → world: a `SwapRequestMsg` (incarnation: the client's nonce).
    SwapRequest = 7,
    /// World → swap client: a `SwapReplyMsg`.
    SwapReply = 8,
    /// Either way, no payload: the sender's link is closing.
    Goodbye = 9,
}

impl Kind {
    const ALL: [Kind; 9] = [
        Kind::Hello,
        Kind::Welcome,
        Kind::Scan,
        Kind::Control,
        Kind::Command,
        Kind::Status,
        Kind::SwapRequest,
        Kind::SwapReply,
        Kind::Goodbye,
    ];
}

/// A datagram read back: its header and its payload's bytes.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    /// What it carries.
    pub kind: Kind,
    /// The robot it concerns.
    pub robot: usize,
    /// The incarnation (agent nonce) or swap client it concerns.
    pub incarnation: u64,
    /// The wire message's bytes.
    pub payload: &'a [u8],
}

impl<'a> Frame<'a> {
    /// The datagram of `kind` about `robot` and `incarnation` carrying `msg`.
    pub fn encode<T: bytemuck::Pod>(
        kind: Kind,
        robot: usize,
        incarnation: u64,
        msg: &T,
    ) -> Vec<u8> {
        let mut bytes = Frame::encode_bare(kind, robot, incarnation);
        bytes.extend_from_slice(message_bytes(msg));
        bytes
    }

    /// The datagram of `kind` about `robot` and `incarnation`, without payload.
    pub fn encode_bare(kind: Kind, robot: usize, incarnation: u64) -> Vec<u8> {
        let mut bytes = Vec::with_capacity(HEADER_LEN);
        bytes.extend_from_slice(&MAGIC);
        bytes.extend_from_slice(&(kind as u32).to_ne_bytes());
        bytes.extend_from_slice(&u32::try_from(robot).unwrap_or(u32::MAX).to_ne_bytes());
        bytes.extend_from_slice(&0u32.to_ne_bytes());
        bytes.extend_from_slice(&incarnation.to_ne_bytes());
        bytes
    }

    /// Reads a datagram's header; a datagram of another program or version is an error.
    pub fn decode(bytes: &'a [u8]) -> Result<Frame<'a>, WireError> {
        let malformed = |reason: String| WireError::Malformed {
            message: "unix datagram",
            reason,
        };
        let (header, payload) = bytes
            .split_at_checked(HEADER_LEN)
            .ok_or_else(|| malformed(format!("{} bytes, under a header", bytes.len())))?;
        let word = |at: usize| {
            u32::from_ne_bytes([header[at], header[at + 1], header[at + 2], header[at + 3]])
        };
        if header[..4] != MAGIC {
            return Err(malformed("not this transport's datagram".into()));
        }
        let code = word(4);
        let kind =
            Kind::ALL
                .into_iter()
                .find(|k| *k as u32 == code)
                .ok_or(WireError::UnknownKind {
                    message: "unix datagram",
                    kind: code,
                })?;
        let mut incarnation = [0u8; 8];
        incarnation.copy_from_slice(&header[16..24]);
        Ok(Frame {
            kind,
            robot: word(8) as usize,
            incarnation: u64::from_ne_bytes(incarnation),
            payload,
        })
    }

    /// The payload as the wire message `T` (`what` names it in the error).
    pub fn message<T: bytemuck::Pod>(&self, what: &'static str) -> Result<T, WireError> {
        message_from_bytes(what, self.payload)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_proto::wire::HelloMsg;

    #[test]
    fn a_frame_reads_back_and_a_strangers_datagram_is_refused() {
        let hello = HelloMsg {
            pid: 7,
            reserved: 0,
            nonce: 42,
            proof: [3; 32],
        };
        let bytes = Frame::encode(Kind::Hello, 2, 42, &hello);
        let frame = Frame::decode(&bytes).unwrap();
        assert_eq!(
            (frame.kind, frame.robot, frame.incarnation),
            (Kind::Hello, 2, 42)
        );
        let back: HelloMsg = frame.message("hello").unwrap();
        assert_eq!((back.pid, back.nonce, back.proof), (7, 42, [3; 32]));
        assert!(Frame::decode(b"short").is_err());
        assert!(Frame::decode(&[0u8; 40]).is_err());
        let mut unknown = Frame::encode_bare(Kind::Goodbye, 0, 1);
        unknown[4] = 99;
        assert!(matches!(
            Frame::decode(&unknown),
            Err(WireError::UnknownKind { kind: 99, .. })
        ));
        assert!(
            frame
                .message::<formation_proto::wire::ScanMsg>("scan")
                .is_err()
        );
    }
}
