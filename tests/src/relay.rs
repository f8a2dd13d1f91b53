//! A TCP relay on 127.0.0.1 that can reset every connection it carries at once, for the tests of
//! a link that drops mid-run (issue 36): what a Wi-Fi access point or a NAT that forgets a
//! connection does to both ends.

use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
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
        let (kept, stopped) = (Arc::clone(&streams), Arc::clone(&stop));
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
                for (from, to) in [(&agent, &world), (&world, &agent)] {
                    let (from, to) = (
                        from.try_clone().expect("a stream"),
                        to.try_clone().expect("a stream"),
                    );
                    std::thread::spawn(move || pump(from, to));
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
            acceptor: Some(acceptor),
        }
    }

    /// Closes every connection carried so far, both ways at once; returns how many links.
    pub fn reset(&self) -> usize {
        let streams = std::mem::take(&mut *self.streams.lock().expect("streams"));
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

/// Copies `from` to `to` until either closes.
fn pump(mut from: TcpStream, mut to: TcpStream) {
    let _ = std::io::copy(&mut from, &mut to);
    let _ = to.shutdown(Shutdown::Both);
    let _ = from.shutdown(Shutdown::Both);
}
