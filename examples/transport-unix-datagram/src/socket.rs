//! The sockets: a bound one that unlinks its path when dropped ([`BoundSocket`]), its receive
//! that waits or not ([`BoundSocket::receive`]), a probe that tells whether anyone listens on a
//! path ([`listening`]), a link's inbox and the loop that takes every datagram waiting in it ([`Inbox`], [`Pump`]), and the errors of a send that mean "nobody there" ([`peer_gone`]) or
//! "the receiver is full" ([`receiver_full`]).

use std::io::ErrorKind;
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::time::Duration;

use formation_proto::wire::WireError;

use crate::error::DatagramError;
use crate::frame::{Frame, MAX_DATAGRAM};

/// The most bytes of a Unix socket path (`sun_path` less its terminating zero).
const MAX_PATH: usize = 107;

/// A datagram socket bound to a path of the run's folder, unlinked when dropped.
#[derive(Debug)]
pub struct BoundSocket {
    socket: UnixDatagram,
    path: PathBuf,
}

impl BoundSocket {
    /// Binds a socket at `path`, refusing a path too long for a socket address.
    pub fn bind(path: PathBuf) -> Result<BoundSocket, DatagramError> {
        check_length(&path)?;
        let socket = UnixDatagram::bind(&path).map_err(DatagramError::io("binding", &path))?;
        Ok(BoundSocket { socket, path })
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Receives one datagram into `buffer` and returns its length: at once (`wait` `None`), or
    /// waiting up to `wait`; `None` when nothing came (or a signal interrupted the wait).
    pub fn receive(
        &self,
        buffer: &mut [u8],
        wait: Option<Duration>,
    ) -> Result<Option<usize>, DatagramError> {
        let receiving = DatagramError::io("receiving on", &self.path);
        let mode = match wait.filter(|w| !w.is_zero()) {
            None => self.socket.set_nonblocking(true),
            Some(wait) => self
                .socket
                .set_nonblocking(false)
                .and_then(|()| self.socket.set_read_timeout(Some(wait))),
        };
        mode.map_err(DatagramError::io("setting up", &self.path))?;
        match self.socket.recv(buffer) {
            Ok(len) => Ok(Some(len)),
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                ) =>
            {
                Ok(None)
            }
            Err(e) => Err(receiving(e)),
        }
    }
}

/// A link's bound socket with the buffer its datagrams are received into.
#[derive(Debug)]
pub struct Inbox {
    socket: BoundSocket,
    buffer: Vec<u8>,
}

impl Inbox {
    /// Receives on `socket` into a buffer of [`MAX_DATAGRAM`] bytes.
    pub fn new(socket: BoundSocket) -> Inbox {
        Inbox {
            socket,
            buffer: vec![0; MAX_DATAGRAM],
        }
    }
}

/// A link's side that takes its datagrams from its [`Inbox`] and files each one
/// ([`Pump::pump`]).
pub trait Pump {
    /// The link's inbox.
    fn inbox(&mut self) -> &mut Inbox;

    /// Who drops a malformed datagram, as the warning names it.
    fn who(&self) -> String;

    /// Files one well-formed datagram.
    fn file(&mut self, frame: Frame<'_>) -> Result<(), WireError>;

    /// Takes every datagram waiting, first waiting up to `wait` for one; whether any came. A
    /// malformed datagram is said and dropped.
    fn pump(&mut self, wait: Option<Duration>) -> Result<bool, DatagramError> {
        let mut buffer = std::mem::take(&mut self.inbox().buffer);
        let mut wait = wait;
        let mut any = false;
        let result = loop {
            match self.inbox().socket.receive(&mut buffer, wait.take()) {
                Ok(Some(len)) => {
                    any = true;
                    if let Err(e) = Frame::decode(&buffer[..len]).and_then(|f| self.file(f)) {
                        tracing::warn!("{}: dropped a datagram: {e}", self.who());
                    }
                }
                Ok(None) => break Ok(any),
                Err(e) => break Err(e),
            }
        };
        self.inbox().buffer = buffer;
        result
    }
}

impl Drop for BoundSocket {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// `Ok` unless `path` is too long for a socket address.
pub fn check_length(path: &Path) -> Result<(), DatagramError> {
    let len = path.as_os_str().len();
    if len > MAX_PATH {
        return Err(DatagramError::PathTooLong {
            path: path.to_path_buf(),
            len,
            max: MAX_PATH,
        });
    }
    Ok(())
}

/// A socket connected to `path`, sending without blocking, or the error saying why not.
pub fn connected(path: &Path) -> std::io::Result<UnixDatagram> {
    let socket = UnixDatagram::unbound()?;
    socket.connect(path)?;
    socket.set_nonblocking(true)?;
    Ok(socket)
}

/// Whether a live socket is bound at `path` (a process that died leaves its path unbound: a
/// connection is refused).
pub fn listening(path: &Path) -> bool {
    UnixDatagram::unbound().is_ok_and(|socket| socket.connect(path).is_ok())
}

/// Sends `bytes` to `path` once, from a socket of its own; whether it was delivered.
pub fn send_once(path: &Path, bytes: &[u8]) -> Result<bool, DatagramError> {
    match connected(path).and_then(|socket| socket.send(bytes)) {
        Ok(_) => Ok(true),
        Err(e) if peer_gone(&e) || receiver_full(&e) => Ok(false),
        Err(e) => Err(DatagramError::io("sending to", path)(e)),
    }
}

/// Whether a send failed because nobody listens there any more.
pub fn peer_gone(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        ErrorKind::ConnectionRefused | ErrorKind::NotFound | ErrorKind::NotConnected
    )
}

/// Whether a send failed because the receiver's queue is full (or its wait timed out).
pub fn receiver_full(e: &std::io::Error) -> bool {
    matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut)
}
