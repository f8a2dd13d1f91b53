//! A packet capture without tcpdump, for the tests that read what crosses the link between two
//! network namespaces (issue 36: a TLS team's link holds no scan or command in clear).
//!
//! The `packet-capture` binary of this package runs inside a namespace (`ip netns exec`), opens
//! an `AF_PACKET` raw socket for every protocol ([`packet_socket`], root only) and writes every
//! frame of that namespace's interfaces to a pcap file ([`capture_until`]) until its standard
//! input closes; Wireshark or tcpdump read the file where they exist. [`PacketCapture`] starts
//! and ends it from a test. [`TcpStreams::read`] then puts the TCP segments of the file back in
//! order, one byte stream per direction of each connection, so that a test searches what an
//! eavesdropper on the link would read, whatever the segmenting. A stream whose segments do not
//! join (the socket dropped frames) counts its gaps, so a test can tell an incomplete capture
//! from a clean one.

use std::io::{Read as _, Write};
use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use socket2::{Domain, Protocol, Socket, Type};

use crate::{Finished, LiveProcess};

/// Linux's `ETH_P_ALL`: every protocol.
const ETH_P_ALL: u16 = 0x0003;
/// The most bytes kept of one frame (a veth hands over segmentation-offload frames up to 64 KiB).
pub const SNAP_LEN: usize = 1 << 18;
/// pcap's link type for Ethernet (loopback and veth frames both carry an Ethernet header).
const LINKTYPE_ETHERNET: u32 = 1;
/// How long one read waits before the stop flag is looked at again.
const POLL: Duration = Duration::from_millis(100);

/// A raw packet socket of the calling process's network namespace, receiving every frame of
/// every interface in both directions. Needs root (`CAP_NET_RAW`).
pub fn packet_socket() -> std::io::Result<Socket> {
    let protocol = Protocol::from(i32::from(ETH_P_ALL.to_be()));
    let socket = Socket::new(Domain::PACKET, Type::RAW, Some(protocol))?;
    // The kernel caps this at net.core.rmem_max; the reader keeps up with a test's traffic.
    socket.set_recv_buffer_size(8 << 20)?;
    socket.set_read_timeout(Some(POLL))?;
    Ok(socket)
}

/// Writes every frame `socket` receives to `out` as a pcap file until `stop` is set; the number
/// of frames written.
pub fn capture_until(socket: &Socket, stop: &AtomicBool, out: impl Write) -> std::io::Result<u64> {
    let mut out = std::io::BufWriter::new(out);
    // The pcap header: magic, version 2.4, GMT, accuracy, snap length, link type.
    out.write_all(&0xa1b2_c3d4_u32.to_le_bytes())?;
    out.write_all(&2u16.to_le_bytes())?;
    out.write_all(&4u16.to_le_bytes())?;
    for word in [0u32, 0, SNAP_LEN as u32, LINKTYPE_ETHERNET] {
        out.write_all(&word.to_le_bytes())?;
    }
    let mut frame = vec![0u8; SNAP_LEN];
    let mut frames = 0;
    let mut reader = socket;
    while !stop.load(Ordering::Relaxed) {
        let n = match reader.read(&mut frame) {
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::Interrupted
                ) =>
            {
                continue;
            }
            Err(e) => return Err(e),
        };
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default();
        let length = u32::try_from(n).unwrap_or(u32::MAX);
        for word in [
            u32::try_from(now.as_secs()).unwrap_or(u32::MAX),
            now.subsec_micros(),
            length,
            length,
        ] {
            out.write_all(&word.to_le_bytes())?;
        }
        out.write_all(&frame[..n])?;
        frames += 1;
    }
    out.flush()?;
    Ok(frames)
}

/// The `packet-capture` binary running in a namespace, writing its pcap file.
pub struct PacketCapture {
    process: LiveProcess,
    file: PathBuf,
}

impl PacketCapture {
    /// Starts `command` (the `packet-capture` binary, as `ip netns exec NS` runs it) writing to
    /// `file`, and waits until its socket is open, so that nothing sent after this returns
    /// escapes it.
    pub fn start(mut command: Command, file: &Path) -> PacketCapture {
        command.arg(file);
        let mut process = LiveProcess::spawn_with_input(command, Some(""));
        let capturing = process.wait_for_line(Duration::from_secs(30), |l| l == "capturing");
        assert!(capturing.is_some(), "{}", process.describe());
        PacketCapture {
            process,
            file: file.to_path_buf(),
        }
    }

    /// Ends the capture and reads its TCP streams back, with the capture's own output.
    pub fn finish(mut self) -> (TcpStreams, Finished) {
        self.process.close_input();
        let finished = self.process.finish(Duration::from_secs(30));
        finished.assert_success();
        let streams =
            TcpStreams::read(&self.file).unwrap_or_else(|e| panic!("{e}\n{}", finished.describe()));
        (streams, finished)
    }
}

/// One direction of one TCP connection, as it crossed the capture, in sequence order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TcpStream {
    /// The sender.
    pub from: SocketAddrV4,
    /// The receiver.
    pub to: SocketAddrV4,
    /// Every payload byte, in sequence order, each once (retransmissions folded in).
    pub bytes: Vec<u8>,
    /// Places where the next captured segment starts after the bytes so far end: frames the
    /// capture did not see.
    pub gaps: usize,
}

impl TcpStream {
    /// Whether `pattern` occurs in the stream.
    pub fn holds(&self, pattern: &[u8]) -> bool {
        !pattern.is_empty() && self.bytes.windows(pattern.len()).any(|w| w == pattern)
    }
}

/// Every TCP stream of an IPv4 capture.
#[derive(Debug, Clone, Default)]
pub struct TcpStreams {
    /// One per direction of each connection, in order of first appearance.
    pub streams: Vec<TcpStream>,
}

/// One captured TCP segment.
struct Segment {
    from: SocketAddrV4,
    to: SocketAddrV4,
    seq: u32,
    syn: bool,
    payload: Vec<u8>,
}

impl TcpStreams {
    /// The streams of the pcap file at `path` (as [`capture_until`] writes it).
    pub fn read(path: &Path) -> Result<TcpStreams, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("reading {}: {e}", path.display()))?;
        TcpStreams::from_pcap(&bytes).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// The streams of a little-endian, microsecond, Ethernet pcap file's bytes.
    pub fn from_pcap(bytes: &[u8]) -> Result<TcpStreams, String> {
        let header = bytes.get(..24).ok_or("shorter than a pcap header")?;
        if header[..4] != 0xa1b2_c3d4_u32.to_le_bytes() {
            return Err("not a little-endian pcap file".into());
        }
        let mut segments = Vec::new();
        let mut at = 24;
        while at < bytes.len() {
            let record = bytes.get(at..at + 16).ok_or("a record header cut short")?;
            let length = u32::from_le_bytes([record[8], record[9], record[10], record[11]]);
            let start = at + 16;
            let end = start + length as usize;
            let frame = bytes.get(start..end).ok_or("a frame cut short")?;
            segments.extend(tcp_segment(frame));
            at = end;
        }
        Ok(TcpStreams::assemble(segments))
    }

    /// The segments put in order, one stream per direction of each connection.
    fn assemble(segments: Vec<Segment>) -> TcpStreams {
        let mut flows: Vec<((SocketAddrV4, SocketAddrV4), Vec<Segment>)> = Vec::new();
        for segment in segments {
            let key = (segment.from, segment.to);
            match flows.iter_mut().find(|(k, _)| *k == key) {
                Some((_, list)) => list.push(segment),
                None => flows.push((key, vec![segment])),
            }
        }
        let streams = flows
            .into_iter()
            .map(|((from, to), list)| {
                let (bytes, gaps) = join(&list);
                TcpStream {
                    from,
                    to,
                    bytes,
                    gaps,
                }
            })
            .collect();
        TcpStreams { streams }
    }

    /// The streams sent to `to` by `from` (either address: any port).
    pub fn from_to(&self, from: Ipv4Addr, to: Ipv4Addr) -> impl Iterator<Item = &TcpStream> {
        self.streams
            .iter()
            .filter(move |s| *s.from.ip() == from && *s.to.ip() == to)
    }
}

/// The payload bytes of one direction's segments in sequence order, and the gaps between them.
/// Sequence numbers are read relative to the first segment's (they wrap at 2³²); the stream
/// starts after a SYN when one was seen, else at the earliest segment.
fn join(segments: &[Segment]) -> (Vec<u8>, usize) {
    let Some(first) = segments.first() else {
        return (Vec::new(), 0);
    };
    let relative = |seq: u32| i64::from(seq.wrapping_sub(first.seq) as i32);
    let syn = segments.iter().find(|s| s.syn).map(|s| relative(s.seq) + 1);
    let mut placed: Vec<(i64, &[u8])> = segments
        .iter()
        .filter(|s| !s.payload.is_empty())
        .map(|s| (relative(s.seq), s.payload.as_slice()))
        .collect();
    placed.sort_by_key(|(offset, _)| *offset);
    let Some(start) = syn.or_else(|| placed.first().map(|(offset, _)| *offset)) else {
        return (Vec::new(), 0);
    };
    let mut bytes = Vec::new();
    let mut end = start;
    let mut gaps = 0;
    for (offset, payload) in placed {
        let length = payload.len() as i64;
        if offset + length <= end {
            continue;
        }
        if offset > end {
            gaps += 1;
            bytes.extend_from_slice(payload);
        } else {
            bytes.extend_from_slice(&payload[(end - offset) as usize..]);
        }
        end = offset + length;
    }
    (bytes, gaps)
}

/// The TCP segment of an Ethernet frame carrying IPv4, if it is one.
fn tcp_segment(frame: &[u8]) -> Option<Segment> {
    const ETHERNET: usize = 14;
    if frame.get(12..14)? != [0x08, 0x00] {
        return None;
    }
    let ip = frame.get(ETHERNET..)?;
    let version_ihl = *ip.first()?;
    if version_ihl >> 4 != 4 || *ip.get(9)? != 6 {
        return None;
    }
    let ip_header = usize::from(version_ihl & 0x0f) * 4;
    let total = usize::from(u16::from_be_bytes([*ip.get(2)?, *ip.get(3)?]));
    // Segmentation offload may leave the total length 0; the frame's end bounds the packet.
    let ip = if total >= ip_header && total <= ip.len() {
        &ip[..total]
    } else {
        ip
    };
    let tcp = ip.get(ip_header..)?;
    let tcp_header = usize::from(tcp.get(12)? >> 4) * 4;
    let address = |at: usize| Some(Ipv4Addr::new(ip[at], ip[at + 1], ip[at + 2], ip[at + 3]));
    let port = |at: usize| Some(u16::from_be_bytes([*tcp.get(at)?, *tcp.get(at + 1)?]));
    Some(Segment {
        from: SocketAddrV4::new(address(12)?, port(0)?),
        to: SocketAddrV4::new(address(16)?, port(2)?),
        seq: u32::from_be_bytes(tcp.get(4..8)?.try_into().ok()?),
        syn: tcp.get(13)? & 0x02 != 0,
        payload: tcp.get(tcp_header..)?.to_vec(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An Ethernet frame of one IPv4 TCP segment from 10.0.0.1:1000 to 10.0.0.2:2000.
    fn frame(seq: u32, syn: bool, payload: &[u8]) -> Vec<u8> {
        let mut frame = vec![0u8; 12];
        frame.extend_from_slice(&[0x08, 0x00]);
        let total = (20 + 20 + payload.len()) as u16;
        let mut ip = vec![
            0x45, 0, 0, 0, 0, 0, 0, 0, 64, 6, 0, 0, 10, 0, 0, 1, 10, 0, 0, 2,
        ];
        ip[2..4].copy_from_slice(&total.to_be_bytes());
        frame.extend_from_slice(&ip);
        let mut tcp = vec![0u8; 20];
        tcp[0..2].copy_from_slice(&1000u16.to_be_bytes());
        tcp[2..4].copy_from_slice(&2000u16.to_be_bytes());
        tcp[4..8].copy_from_slice(&seq.to_be_bytes());
        tcp[12] = 5 << 4;
        tcp[13] = if syn { 0x02 } else { 0x10 };
        frame.extend_from_slice(&tcp);
        frame.extend_from_slice(payload);
        frame
    }

    fn pcap(frames: &[Vec<u8>]) -> Vec<u8> {
        let mut bytes = Vec::new();
        bytes.extend_from_slice(&0xa1b2_c3d4_u32.to_le_bytes());
        bytes.extend_from_slice(&[2, 0, 4, 0]);
        bytes.extend_from_slice(&[0u8; 16]);
        for frame in frames {
            bytes.extend_from_slice(&[0u8; 8]);
            let length = (frame.len() as u32).to_le_bytes();
            bytes.extend_from_slice(&length);
            bytes.extend_from_slice(&length);
            bytes.extend_from_slice(frame);
        }
        bytes
    }

    #[test]
    fn segments_out_of_order_repeated_and_across_the_wrap_join_into_one_stream() {
        let isn = u32::MAX - 3;
        let frames = [
            frame(isn, true, b""),
            frame(isn.wrapping_add(1 + 4), false, b"efgh"),
            frame(isn.wrapping_add(1), false, b"abcd"),
            frame(isn.wrapping_add(1 + 2), false, b"cdef"),
            frame(isn.wrapping_add(1 + 8), false, b"ij"),
        ];
        let streams = TcpStreams::from_pcap(&pcap(&frames)).expect("a capture");
        assert_eq!(streams.streams.len(), 1);
        let stream = &streams.streams[0];
        assert_eq!(stream.bytes, b"abcdefghij");
        assert_eq!(stream.gaps, 0);
        assert!(stream.holds(b"ghij"));
        assert!(!stream.holds(b"ja"));
        let from = Ipv4Addr::new(10, 0, 0, 1);
        let to = Ipv4Addr::new(10, 0, 0, 2);
        assert_eq!(streams.from_to(from, to).count(), 1);
        assert_eq!(streams.from_to(to, from).count(), 0);
    }

    #[test]
    fn a_missing_segment_is_a_gap() {
        let frames = [frame(100, false, b"abcd"), frame(108, false, b"ijkl")];
        let streams = TcpStreams::from_pcap(&pcap(&frames)).expect("a capture");
        assert_eq!(streams.streams[0].gaps, 1);
        assert_eq!(streams.streams[0].bytes, b"abcdijkl");
    }

    #[test]
    fn frames_of_other_protocols_are_left_out_and_a_cut_file_is_refused() {
        let mut other = frame(1, false, b"x");
        other[12] = 0x86;
        let streams = TcpStreams::from_pcap(&pcap(&[other])).expect("a capture");
        assert!(streams.streams.is_empty());
        let whole = pcap(&[frame(1, false, b"abc")]);
        assert!(TcpStreams::from_pcap(&whole[..whole.len() - 1]).is_err());
        assert!(TcpStreams::from_pcap(b"not a capture at all").is_err());
    }
}
