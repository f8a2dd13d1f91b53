//! The suite's pilot and models. A model is a small text file whose text is its id: `fast…`
//! drives both wheels at [`FAST`], any other at [`SLOW`], and `bad…` does not load, so a test
//! reads from the commands alone which model (and so which agent) drove a robot. The file is
//! read when the model loads, so a model that travels as bytes (a swap over Zenoh) is the same
//! model.
//!
//! Each agent's pilot passes every decision through a [`Gate`] that the test holds: it can stop
//! the agent's decisions (an agent that hangs, then recovers) or make every one of them late.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Duration;

use formation_proto::{Goal, LidarSpec, WheelCmd};
use formation_runtime::agent::{BoxError, Pilot, PilotMaker};
use formation_test_kit::TempDir;

/// What the slow model commands.
pub const SLOW: WheelCmd = WheelCmd {
    left: 0.1,
    right: 0.1,
};

/// What the fast model commands.
pub const FAST: WheelCmd = WheelCmd {
    left: 0.5,
    right: 0.5,
};

/// The suite's model files, in a scratch folder of their own.
pub struct Models {
    dir: TempDir,
}

impl Default for Models {
    fn default() -> Self {
        Models::new()
    }
}

impl Models {
    /// Writes `slow`, `fast` and `bad`.
    pub fn new() -> Models {
        let dir = TempDir::new("models");
        for id in ["slow", "fast", "bad"] {
            std::fs::write(dir.path().join(id), id).expect("writing a suite model");
        }
        Models { dir }
    }

    /// The model file `id` (`slow`, `fast` or `bad`).
    pub fn path(&self, id: &str) -> PathBuf {
        self.dir.path().join(id)
    }
}

/// A loaded model: its id and what it commands.
#[derive(Debug, Clone)]
pub struct Model {
    id: String,
    cmd: WheelCmd,
}

/// How a test holds an agent's decisions.
#[derive(Debug, Default)]
struct GateState {
    /// Decisions still allowed; `None`: any number.
    permits: Option<u64>,
    /// How long each decision takes.
    late: Duration,
}

/// What a test holds an agent's pilot by: its decisions wait while the gate is held, and each
/// takes `late` longer once set.
#[derive(Debug, Default)]
pub struct Gate {
    state: Mutex<GateState>,
    changed: Condvar,
}

impl Gate {
    fn lock(&self) -> MutexGuard<'_, GateState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Holds every decision from now on until [`Gate::release`].
    pub fn hold(&self) {
        self.lock().permits = Some(0);
    }

    /// Lets every decision through again.
    pub fn release(&self) {
        self.lock().permits = None;
        self.changed.notify_all();
    }

    /// Makes every decision from now on take `late` longer.
    pub fn make_late(&self, late: Duration) {
        self.lock().late = late;
    }

    /// One decision: waits while the gate is held, then takes as long as it was told to.
    fn pass(&self) {
        let mut state = self
            .changed
            .wait_while(self.lock(), |s| s.permits == Some(0))
            .unwrap_or_else(|e| e.into_inner());
        if let Some(permits) = &mut state.permits {
            *permits -= 1;
        }
        let late = state.late;
        drop(state);
        std::thread::sleep(late);
    }
}

/// Loads the suite's models for pilots held by one gate.
pub struct SuitePilots {
    /// The gate of this agent's pilot.
    pub gate: Arc<Gate>,
}

/// Drives at its model's speed, whatever it sees.
pub struct SuitePilot {
    model: Model,
    gate: Arc<Gate>,
}

impl SuitePilot {
    /// The pilot of the model at `path`, held by `gate`.
    pub fn load(path: &Path, gate: Arc<Gate>) -> Result<SuitePilot, BoxError> {
        let model = SuitePilots {
            gate: Arc::clone(&gate),
        }
        .load(path)?;
        Ok(SuitePilot { model, gate })
    }
}

impl PilotMaker for SuitePilots {
    type Model = Model;
    type Pilot = SuitePilot;

    fn load(&self, path: &Path) -> Result<Model, BoxError> {
        let id = std::fs::read_to_string(path)?.trim().to_owned();
        if id.starts_with("bad") {
            return Err(format!("{id} is not a model").into());
        }
        let cmd = if id.starts_with("fast") { FAST } else { SLOW };
        Ok(Model { id, cmd })
    }

    fn model_id<'m>(&self, model: &'m Model) -> &'m str {
        &model.id
    }

    fn pilot(&self, model: Model, _: LidarSpec) -> Result<SuitePilot, BoxError> {
        Ok(SuitePilot {
            model,
            gate: Arc::clone(&self.gate),
        })
    }
}

impl Pilot for SuitePilot {
    type Model = Model;

    fn model_id(&self) -> &str {
        &self.model.id
    }

    fn perceive(&mut self, ranges: &[f32], _goal: &Goal) -> Result<(), BoxError> {
        if ranges.is_empty() {
            Err("an empty scan".into())
        } else {
            Ok(())
        }
    }

    fn decide(&mut self, _: f64, _: &Goal) -> Result<WheelCmd, BoxError> {
        self.gate.pass();
        Ok(self.model.cmd)
    }

    fn swap(&mut self, model: Model) -> Result<(), BoxError> {
        self.model = model;
        Ok(())
    }

    fn set_wheel_limits(&mut self, _wheels: formation_proto::WheelLimits) {}
}
