//! Recording a run to MCAP, for Foxglove, Rerun, ROS 2 tools and a later replay.
//!
//! A recording is an MCAP file with the `ros2` profile ([`mod@file`]): each robot's scan, odometry,
//! commanded Twist and `/tf`, the `/tf_static` frames, the team's goal and the formation's edges
//! with their errors as markers ([`edges`]), all CDR with their `ros2msg` schemas, the same
//! messages as the live ROS 2 team (`formation_ros2::team`); the run's metadata (scenario, seeds,
//! models with their SHA-256) as a metadata record, a model from outside the shipped folder as
//! an attachment ([`setup`]), and so is a model swapped in during the run, with a record that maps
//! its model id to it ([`swap`]); and a replay channel per robot that holds, bit for bit, what its
//! agent received and sent ([`replay`]). Chunks are zstd-compressed and hold one second of
//! simulated time at most, written out as they close, so memory stays bounded and a crash
//! leaves a file that a streaming reader reads up to its last chunk.
//!
//! The topics and each tick's messages are defined once, in [`topics`], which the live view
//! (`formation run --foxglove`, formation-cli) serves as well.
//! The tick loop hands each tick ([`tick`]) to a writer thread ([`recorder`]); where recordings
//! go and the checks before a run are in [`target`], the errors in [`error`]. A replay reads a
//! recording back in one streaming pass ([`read`]) and finds its models, checked against their
//! hashes ([`models`]); running them is the `formation replay` command's (formation-cli), since
//! this crate builds no ONNX Runtime.
//! A recorder of a live team from outside (`formation record --connect`) gets the same ticks
//! over the network in the encoding of [`live`], and writes the same file.

pub mod bounds;
pub mod edges;
pub mod error;
pub mod file;
pub mod live;
mod model_files;
pub mod models;
pub mod read;
mod read_error;
pub mod recorder;
pub mod replay;
pub mod setup;
pub mod swap;
pub mod target;
pub mod tick;
pub mod topics;

pub use error::RecordError;
pub use file::{RecordingFile, RecordingSummary};
pub use read::{ReadError, RecordingItem, RecordingReader, RunInfo};
pub use recorder::{RecordedController, Recorder, final_sample};
pub use replay::ReplayStep;
pub use setup::{LaunchInfo, RecordingSetup, TeamSetup};
pub use swap::{SwapStorage, SwappedModel};
pub use target::{RecordSettings, RecordTarget};
pub use tick::{FinalSample, RunEnd, SentCommand, TickRecord};
