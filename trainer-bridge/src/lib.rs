//! The dataset format shared by the Rust collector and the PyTorch trainer, and the bridge that runs the trainer.
//!
//! - [`dataset`] writes and reads the on-disk dataset: a directory with a `manifest.json` and
//!   `shard-NNNNNN.safetensors` files, every file written atomically, so an interrupted collection
//!   leaves a valid dataset of its finished shards. The Python package `formation_trainer` (in
//!   `trainer-bridge/python`) reads the same format with numpy and safetensors only.
//! - [`dagger_part`] writes and reads a DAgger part: one share of an iteration's labelled
//!   samples (a Ray task's output), and appends an iteration's parts to the dataset in run order.
//! - [`difference`] names the first field in which two sets of settings differ, for the refusals
//!   to mix a dataset's, a part's or an evaluation shard's settings.
//! - [`train`] runs `python -m formation_trainer train` as a subprocess, streams its progress and
//!   parses its final report; the trainer writes the ONNX model, a `.pt` checkpoint and the loss curve.

pub mod dagger_part;
pub mod dataset;
pub mod difference;
mod digest;
pub mod label_law;
pub mod train;
