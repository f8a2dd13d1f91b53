//! One agent of the suite on a thread of its own, as a process would run it: it connects over
//! the rig's transport, greets, and runs until the world shuts it down or the test stops it (as
//! a launcher closing its input does). The test holds its pilot by the [`Gate`].

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use formation_runtime::agent::{AgentExit, AgentLoop, PilotMaker, error_chain};
use formation_runtime::clock::SystemClock;
use formation_runtime::link::{AgentLink, AgentLinkError};

use crate::pilot::{Gate, SuitePilots};

/// How long an agent waits for the world to answer its greeting.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(20);

/// How an agent's thread ended: its loop's exit, or the error that ended it (a refused
/// greeting among them), as text.
pub type Ending = Result<AgentExit, String>;

/// An agent running on its own thread.
pub struct Agent {
    gate: Arc<Gate>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Ending>>,
}

impl Agent {
    /// Runs `body` on a thread of its own with a fresh gate and stop flag.
    pub fn spawn(
        body: impl FnOnce(Arc<Gate>, Arc<AtomicBool>) -> Ending + Send + 'static,
    ) -> Agent {
        let gate = Arc::new(Gate::default());
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (gate, stop) = (Arc::clone(&gate), Arc::clone(&stop));
            std::thread::spawn(move || body(gate, stop))
        };
        Agent {
            gate,
            stop,
            thread: Some(thread),
        }
    }

    /// The gate its pilot's decisions pass.
    pub fn gate(&self) -> &Gate {
        &self.gate
    }

    /// Whether its thread has ended.
    pub fn ended(&self) -> bool {
        self.thread.as_ref().is_none_or(JoinHandle::is_finished)
    }

    /// Waits for its thread to end on its own, and says how.
    pub fn finish(mut self) -> Ending {
        let thread = self
            .thread
            .take()
            .expect("an agent's thread is joined once");
        thread
            .join()
            .unwrap_or_else(|_| Err("the agent's thread panicked".into()))
    }

    /// Stops it as its launcher would (the stop flag), and says how it ended.
    pub fn stop(self) -> Ending {
        self.stop.store(true, Ordering::Relaxed);
        self.gate.release();
        self.finish()
    }
}

impl Drop for Agent {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        self.gate.release();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// An agent process of the memory, iceoryx2 or Zenoh transport: connects with `connect`, greets
/// as process `pid` with the model at `model`, and runs the agent loop of run `run`.
pub fn loop_agent<L: AgentLink>(
    connect: impl FnOnce() -> Result<L, AgentLinkError>,
    (model, pid, run): (&Path, u32, &str),
    gate: Arc<Gate>,
    stop: &AtomicBool,
) -> Ending {
    let mut link = connect().map_err(|e| error_chain(&e))?;
    let pilots = Arc::new(SuitePilots { gate });
    let loaded = pilots.load(model).map_err(|e| error_chain(e.as_ref()))?;
    // Polling for scans after each command, as the launcher's agents of a small team do, so
    // that every behaviour is checked with it.
    let mut agent = AgentLoop::new(
        pilots,
        model.to_path_buf(),
        loaded,
        None,
        Arc::new(SystemClock),
    )
    .with_spin(std::time::Duration::from_micros(300));
    agent.greet(&mut link, pid).map_err(|e| error_chain(&e))?;
    agent.run(&mut link, stop, run).map_err(|e| error_chain(&e))
}
