//! The multi-process runtime launcher (placeholder until the runtime lands).

use clap::Args;

/// `formation run`.
#[derive(Debug, Args)]
pub struct RunArgs {}
/// `formation profile`.
#[derive(Debug, Args)]
pub struct ProfileArgs {}
/// `formation swap`.
#[derive(Debug, Args)]
pub struct SwapArgs {}

/// `formation run`.
pub fn run_command(_args: &RunArgs) -> anyhow::Result<()> {
    anyhow::bail!("not yet available")
}
/// `formation profile`.
pub fn profile_command(_args: &ProfileArgs) -> anyhow::Result<()> {
    anyhow::bail!("not yet available")
}
/// `formation swap`.
pub fn swap_command(_args: &SwapArgs) -> anyhow::Result<()> {
    anyhow::bail!("not yet available")
}

/// Clock mode of the world process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClockMode {
    /// Wait for every agent's command each tick.
    Lockstep,
    /// Fixed 20 Hz wall clock.
    Realtime,
}

/// Evaluates runs over real processes.
pub fn eval_over_processes(
    _scenario: &formation_world::Scenario,
    _base_seed: u64,
    _runs: usize,
    _default_model: &std::path::Path,
    _clock: ClockMode,
    _on_run_done: &mut dyn FnMut(usize),
) -> anyhow::Result<Vec<formation_world::Trajectory>> {
    anyhow::bail!("not yet available")
}
