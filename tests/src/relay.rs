//! A TCP relay on 127.0.0.1 that can reset every connection it carries at once, for the tests of
//! a link that drops mid-run (issue 36): what a Wi-Fi access point or a NAT that forgets a
//! connection does to both ends. It can also hold what the agents send (stop reading it), so
//! that a reset then loses it: a message sent just before a drop.

use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// A TCP relay on 127.0.0.1 to the world's endpoint that can reset every connection it
/// carries: what a link reset looks like to both ends.
pub struct ResettingRelay {
    /// The port it listens on, on 127.0.0.1.
    pub port: u16,
    streams: Arc<Mutex<Vec<TcpStream>>>,
    stop: Arc<AtomicBool>,
    /// While set, nothing the agents send is read (it stays in the sockets' buffers).
    hold: Arc<AtomicBool>,
    /// How many resets there were: a connection ends, forwarding nothing more, at the first
    /// after it began.
    resets: Arc<AtomicUsize>,
    acceptor: Option<JoinHandle<()>>,
}

impl ResettingRelay {
    /// A relay forwarding to `world` (`HOST:PORT`).
    pub fn start(world: &str) -> ResettingRelay {
        let listener = TcpListener::bind("127.0.0.1:0").expect("binding the relay");
        listener
            .set_nonblocking(true)
            .expect("a non-blocking listener");
        let port = listener.local_addr().expect("the relay's address").port();
        let streams = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let world = world.to_string();
        let hold = Arc::new(AtomicBool::new(false));
        let resets = Arc::new(AtomicUsize::new(0));
        let (kept, stopped) = (Arc::clone(&streams), Arc::clone(&stop));
        let (held, reset) = (Arc::clone(&hold), Arc::clone(&resets));
        let acceptor = std::thread::spawn(move || {
            while !stopped.load(Ordering::Relaxed) {
                let agent = match listener.accept() {
                    Ok((agent, _)) => agent,
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                        std::thread::sleep(Duration::from_millis(10));
                        continue;
                    }
                    Err(e) => panic!("the relay's accept: {e}"),
                };
                agent.set_nonblocking(false).expect("a blocking stream");
                let Ok(world) = TcpStream::connect(&world) else {
                    continue;
                };
                for (from, to, toward_world) in [(&agent, &world, true), (&world, &agent, false)] {
                    let (from, to) = (
                        from.try_clone().expect("a stream"),
                        to.try_clone().expect("a stream"),
                    );
                    let hold = toward_world.then(|| Arc::clone(&held));
                    let (resets, begun) = (Arc::clone(&reset), reset.load(Ordering::SeqCst));
                    std::thread::spawn(move || {
                        pump(from, to, hold.as_deref(), (&resets, begun));
                    });
                }
                let mut kept = kept.lock().expect("streams");
                kept.push(agent);
                kept.push(world);
            }
        });
        ResettingRelay {
            port,
            streams,
            stop,
            hold,
            resets,
            acceptor: Some(acceptor),
        }
    }

    /// Stops (`true`) or resumes reading what the agents send; a [`ResettingRelay::reset`] while
    /// held loses what was held.
    pub fn hold_toward_world(&self, hold: bool) {
        self.hold.store(hold, Ordering::Relaxed);
    }

    /// Closes every connection carried so far, both ways at once; returns how many links.
    pub fn reset(&self) -> usize {
        let streams = std::mem::take(&mut *self.streams.lock().expect("streams"));
        self.resets.fetch_add(1, Ordering::SeqCst);
        for stream in &streams {
            let _ = stream.shutdown(Shutdown::Both);
        }
        streams.len() / 2
    }
}

impl Drop for ResettingRelay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        self.reset();
        if let Some(acceptor) = self.acceptor.take() {
            let _ = acceptor.join();
        }
    }
}

/// Copies `from` to `to` until either closes or a reset comes (`resets` past `begun`); while
/// `hold` is set, reads nothing, so that a reset loses what was held.
fn pump(
    mut from: TcpStream,
    mut to: TcpStream,
    hold: Option<&AtomicBool>,
    (resets, begun): (&AtomicUsize, usize),
) {
    use std::io::{Read as _, Write as _};
    let mut buffer = [0u8; 16 << 10];
    let reset = || resets.load(Ordering::SeqCst) != begun;
    loop {
        if reset() {
            break;
        }
        if hold.is_some_and(|h| h.load(Ordering::Relaxed)) {
            std::thread::sleep(Duration::from_millis(10));
            continue;
        }
        let n = match from.read(&mut buffer) {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        if reset() || to.write_all(&buffer[..n]).is_err() {
            break;
        }
    }
    let _ = to.shutdown(Shutdown::Both);
    let _ = from.shutdown(Shutdown::Both);
}
