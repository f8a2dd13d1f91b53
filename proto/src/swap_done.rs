//! A model swap an agent reported done: what the world's exchange hands on to its run log and to
//! its recording, one type for both.

use std::path::PathBuf;

/// A swap an agent did: which robot, from which tick on, the model id the agent now reports, and
/// the model file the request named (`None` when the world does not know it) or the bytes that
/// came with it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SwapDone {
    /// The robot.
    pub robot: usize,
    /// The request's id.
    pub request_id: u64,
    /// The first tick the new model decided.
    pub tick: u64,
    /// The id of the model the agent runs now.
    pub model_id: String,
    /// The model file the request named (on the world's host, unless the model came over the
    /// network).
    pub path: Option<PathBuf>,
    /// The model's bytes, when they came over the network with the request (Zenoh); then `path`
    /// is the sender's, informative only.
    pub model: Option<Vec<u8>>,
}
